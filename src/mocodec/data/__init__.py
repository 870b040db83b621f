"""Files that ship inside the package: the bundled clip ``make demo`` codes, the pinned
three.js (MIT, ``three/LICENSE``) the viewer pages and the relay's watch page load, so a wheel
works offline with nothing fetched at install time, and the scripts those pages share."""

from pathlib import Path

HERE = Path(__file__).parent
#: The bundled clip (CMU 02_02, a walk; BVH).
SAMPLE_CLIP = HERE / "sample_walk_02_02.bvh"
#: three.js and the addons the pages import (``make vendor`` refreshes them from npm at the
#: version the Makefile pins).
THREE = HERE / "three"
#: Scripts both the viewer's pages and the relay's watch page load (served at ``/shared/``):
#: ``body.js`` draws the mannequin.
PAGES = HERE / "pages"


def three_is_there() -> bool:
    """Whether three.js and the addons the pages need are in the package."""
    return (THREE / "three.module.js").is_file() and (THREE / "addons" / "controls" / "OrbitControls.js").is_file()
