"""CSM Engine: a real-time deferred render engine for Blender with cascaded sun shadows.

This module owns add-on registration only. It works both as a Blender extension
(4.2+, described by ``blender_manifest.toml``) and as a legacy add-on (3.4-4.1,
described by ``bl_info``). Heavy modules are imported inside ``register()`` so that
importing the package (for example from the pure-Python tests) never needs Blender.
"""

bl_info = {
    "name": "CSM Engine",
    "author": "CSM Engine developers",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "Render Engine > CSM; File > Import > CSM Scene (.json)",
    "description": "Real-time deferred renderer with cascaded shadow maps",
    "category": "Render",
}

_MODULES = ("preferences", "settings", "light_controls", "engine", "operators", "keymap", "ui")


def _modules():
    import importlib
    return [importlib.import_module(".blender." + name, __name__) for name in _MODULES]


def register():
    for module in _modules():
        module.register()


def unregister():
    for module in reversed(_modules()):
        module.unregister()
