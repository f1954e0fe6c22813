"""Packaging: the package list and the assets mapping; every other setting is in pyproject.toml.

The repository keeps the built-in targets, scenes and sweeps in ``assets/`` at its top; they ship
inside the package as ``simcore.assets`` (found through ``importlib.resources``), so a wheel
installed anywhere runs. ``pyproject.toml`` cannot add a mapped folder to the packages it finds,
hence this file (and the data files are listed here too: setuptools takes them from one place:
the assets, and the page's scripts and styles in ``app/static/``).
Each folder under ``assets/`` is a package of data files (``simcore.assets.targets.mro`` holds the
MRO's mesh, material map and credits).
"""

from setuptools import find_namespace_packages, find_packages, setup

ASSETS = "simcore.assets"
asset_folders = [f"{ASSETS}.{name}" for name in find_namespace_packages(where="assets")]

setup(
    packages=[*find_packages(include=["simcore*", "app*"]), "simcore.data", ASSETS, *asset_folders],
    package_dir={ASSETS: "assets"},
    package_data={
        "simcore": ["py.typed"],
        "app": ["static/*.js", "static/*.css"],  # the page's scripts and styles (app.ui.static)
        "simcore.data": ["*.csv"],
        ASSETS: ["*.toml"],
        **{folder: ["*"] for folder in asset_folders},
    },
)
