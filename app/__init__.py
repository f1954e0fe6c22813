"""lmapd-sim's browser app: trame (Vue 3 + Vuetify 3) on top of the simcore imaging chain.

``app.main:main`` starts the server; ``app.engine`` owns the pipeline and the worker thread,
``app.logic`` maps state to scenes and results to view payloads, ``app.ui`` builds the page.
"""
