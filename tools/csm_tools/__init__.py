"""Measuring tools for CSM Engine: the benchmark against EEVEE, the ground-truth comparison
with Cycles, the shadow-quality report, and the benchmark's real-model scenes.

They live beside the add-on, never inside it: nothing here is shipped in the extension or
the legacy zip, and ``csm_engine`` never imports this package. Run them through ``./dev``
(``./dev bench``, ``./dev ground-truth``, ``./dev quality-report``, ``./dev bench-models``),
which puts the repository root and ``tools/`` on ``PYTHONPATH`` for pip ``bpy``.
"""
