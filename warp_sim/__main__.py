"""``python -m warp_sim run SCENE.toml``: see warp_sim/cli.py."""

import sys

from .cli import main

sys.exit(main())
