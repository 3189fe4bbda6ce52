"""The Blender adapters: render engine, snapshot, mesh extraction, scene import, settings,
add-on preferences, operators, keymap, panels, light controls, command line, and every
Blender-version shim (``compat``).

May import ``bpy``, ``mathutils``, ``csm_engine.core`` and ``csm_engine.render``; nothing in
``core`` or ``render`` imports from here.
"""
