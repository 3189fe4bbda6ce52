"""The animation farm: ``python -m csm_engine FILE.blend --frames A-B --output f_####.png
--workers N`` spreads a .blend's frames over Dask workers (``command.py`` on the machine
that asks, ``worker.py`` in each worker process, ``frames.py`` the pure frame and file
name rules). Dask is optional and imported only by ``command.py``, on request; the add-on
never imports this package."""
