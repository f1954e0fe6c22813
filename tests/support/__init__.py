"""Helpers shared by the tests (and scripts): synthetic meshes, a test-only receiver, app and
browser drivers."""
