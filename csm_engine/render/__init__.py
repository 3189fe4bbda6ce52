"""The GPU side: shader library, GPU meshes and the pipeline that executes a shadow plan.

Imports ``gpu`` (lazily, never at import time) and ``csm_engine.core``; never ``bpy``
operators, properties or scene data: everything arrives as a ``FrameSnapshot`` and numpy
arrays, and results leave as a ``RenderResult``.
"""
