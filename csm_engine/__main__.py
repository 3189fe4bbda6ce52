"""``python -m csm_engine [scene.json [screenshot.png]]`` on pip bpy (see cli.py)."""
from csm_engine.blender.cli import main
from csm_engine.blender.compat import exit_process

exit_process(main())
