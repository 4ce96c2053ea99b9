"""`python -m zeus_ros.cli <command>`: the `zeus` entry point without the installed script."""

from __future__ import annotations

from zeus_ros.cli import main

raise SystemExit(main())
