"""The app's logic: state to scene, results to view payloads. No trame imports here except in
``controller``; everything else is plain functions on numpy arrays and simcore objects."""
