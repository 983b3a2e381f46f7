"""``python -m urdaemon``."""

from __future__ import annotations

import sys

from urdaemon.cli import main

sys.exit(main())
