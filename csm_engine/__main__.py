"""``python -m csm_engine [scene.json [screenshot.png]]`` on pip bpy (see cli.py; a .blend
first renders its animation on the farm, see farm/command.py); on a
Python without bpy it says, in one line, how to run it instead."""
from csm_engine.blender.cli import exit_process, main

exit_process(main())
