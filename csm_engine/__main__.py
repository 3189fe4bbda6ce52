"""``python -m csm_engine [scene.json [screenshot.png]]`` on pip bpy (see cli.py)."""
import sys

from csm_engine.cli import main

sys.exit(main())
