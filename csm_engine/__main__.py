"""``python -m csm_engine [scene.json [screenshot.png]]`` on pip bpy (see cli.py)."""
from csm_engine.cli import exit_process, main

exit_process(main())
