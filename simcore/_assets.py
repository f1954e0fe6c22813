"""Where the built-in targets, scenes, sweeps and material rules are: package ``simcore.assets``.

The repository keeps them in ``assets/`` at its top; the packaging maps that folder to the
``simcore.assets`` package (``setup.py``: ``package_dir``), so a wheel installed anywhere carries
them and ``importlib.resources`` finds them, and an editable install (``pip install -e .``) finds
the checkout's folder through the same name.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

_CHECKOUT_ASSETS = Path(__file__).resolve().parent.parent / "assets"


def assets_dir() -> Path:
    """The folder of the built-in assets (``targets/``, ``scenes/``, ``sweeps/``, ...).

    The checkout's ``assets/`` beside the package when it is run from a source tree (its
    ``pyproject.toml`` beside it: ``PYTHONPATH=.``, or an editable install of that tree), else
    ``simcore.assets`` through :mod:`importlib.resources` (a wheel).
    """
    if (_CHECKOUT_ASSETS.parent / "pyproject.toml").is_file() and _CHECKOUT_ASSETS.is_dir():
        # a source tree's own folder first: a checkout imported with PYTHONPATH beside another
        # checkout's editable install reads its own assets, not the installed one's
        return _CHECKOUT_ASSETS
    try:
        root = resources.files("simcore.assets")
    except ModuleNotFoundError:
        return _CHECKOUT_ASSETS
    # installed unpacked (a wheel, or an editable install): a regular package, a real folder
    return Path(str(root))


ASSETS_DIR = assets_dir()
