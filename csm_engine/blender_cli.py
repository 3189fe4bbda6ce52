"""Script for a real Blender binary: ``blender -b -P <this file> -- scene.json shot.png``.

Owns only the bridge from Blender's ``--`` argument convention to ``cli.main``; it works
from a source checkout, an installed extension or a legacy add-on folder alike.
"""
import os
import sys

if __name__ == "__main__":
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    from csm_engine.blender.cli import main, shell_path

    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    # Usage lines and hints name this file as the user reaches it from where they are.
    code = main(argv, prog=f"blender -b -P {shell_path(os.path.abspath(__file__))} --")
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)   # Blender would otherwise exit 0 whatever the script returned
