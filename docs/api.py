"""The API reference, generated from the docstrings with pdoc (``make api``): one HTML page per
public module, in ``build/api/`` (or the folder given), with a search box; it opens offline.

    python docs/api.py [OUT]
"""

from __future__ import annotations

import argparse
import importlib
import inspect
from pathlib import Path

#: The modules a user of the library calls; their submodules follow from these pages' links.
MODULES = [
    "mocodec",
    "mocodec.motion",
    "mocodec.skeleton",
    "mocodec.kinematics",
    "mocodec.rotations",
    "mocodec.reexpress",
    "mocodec.human",
    "mocodec.formats",
    "mocodec.codecs",
    "mocodec.codecs.base",
    "mocodec.ratecontrol",
    "mocodec.metrics",
    "mocodec.analysis",
    "mocodec.crowd",
    "mocodec.scene",
    "mocodec.stream",
    "mocodec.stream.relay.core",
    "mocodec.stream.relay.server",
    "mocodec.numcodecs",
    "mocodec.zarr3",
    "mocodec.errors",
    "mocodec.limits",
    "mocodec.data",
]


def build(out: Path) -> list[Path]:
    """Write the pages into ``out``; returns them."""
    try:
        import pdoc
    except ImportError:
        raise SystemExit("the API page needs pdoc: pip install -e '.[docs]'") from None
    for name in MODULES:  # names a package imports when first used are resolved for pdoc
        module = importlib.import_module(name)
        for attr in getattr(module, "__all__", ()):
            value = getattr(module, attr)
            if not inspect.ismodule(value):  # a submodule has a page of its own
                setattr(module, attr, value)
    pdoc.render.configure(docformat="restructuredtext", search=True, show_source=False)
    pdoc.pdoc(*MODULES, output_directory=out)
    return sorted(out.rglob("*.html"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", nargs="?", default="build/api", help="output folder (default build/api)")
    args = parser.parse_args()
    pages = build(Path(args.out))
    print(f"{len(pages)} pages in {args.out}/ (open {args.out}/index.html)")


if __name__ == "__main__":
    main()
