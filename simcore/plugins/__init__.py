"""The library's plug-in points, on its lowest floor (standard library only): the receivers'
registry (:mod:`simcore.plugins.registry`) and what a receiver declares
(:mod:`simcore.plugins.declaration`).

The scene reads them for the valid ``receiver.kind`` values and the receivers' sections, so they
sit below it; the receivers themselves (:mod:`simcore.receivers`) sit above the scene and
re-export these names.
"""
