"""The app's logic: state to scene, results to view payloads. No trame imports here except in
``controller``; everything else is plain functions on numpy arrays and simcore objects.

What the page's layout (``app.ui``) may read from the logic is declared here (``__all__``); the
UI imports nothing else of it (tests/test_import_layout.py): the lessons' records, the upload's
accepted files and scale range, a preset's description.
"""

from app.logic.lessons import LESSONS
from app.logic.scene_map import preset_text
from app.logic.upload import ALLOWED_SUFFIXES, SCALE_RANGE

__all__ = ["ALLOWED_SUFFIXES", "LESSONS", "SCALE_RANGE", "preset_text"]
