"""``python -m csm_engine [scene.json [screenshot.png]]`` on pip bpy (see cli.py)."""
import os
import sys

from csm_engine.cli import main

code = main()
sys.stdout.flush()
sys.stderr.flush()
# pip bpy 4.2 crashes while tearing down a GPU-context engine at interpreter exit (exit 139
# whatever happened); leave directly so the exit code is the command's own.
os._exit(code)
