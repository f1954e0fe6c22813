"""The built-in targets (meshes, material maps, credits), scenes, sweeps and material rules.

Data only. Installed as the ``simcore.assets`` package (see ``setup.py``), found through
``importlib.resources`` by ``simcore._assets``.
"""
