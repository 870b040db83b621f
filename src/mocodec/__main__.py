"""``python -m mocodec``: the command line."""

import sys

from mocodec.cli import main

sys.exit(main())
