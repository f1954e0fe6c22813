"""Serving the app: the launcher (each tab its own session process, started or forked from the
preloaded parent), the door (who may connect, what a page may send, how much memory it may hold),
the connection guards, and the patches of trame-server and wslink with the releases they were
checked against.

``launcher`` the sessions and the proxy in front of them, by concern in ``caps`` (the limits),
``ending`` (when a session ends), ``children`` (the session processes, started or forked),
``frame_memory`` (the heavy frames' memory budget across sessions, and a session's end of it),
``routes`` (what a request's path and cookies say), ``pages`` (the launcher's own pages) and
``proxy`` (a session's pages and websocket passed to its process); ``zygote`` the sessions'
preloaded parent; ``process`` the serving processes (a session's token and address-space limit,
the launcher's run, the exit status);
``addresses`` what the server prints and trame's options;
``security`` the websocket door (``install``), by concern in ``door`` (the token, origins and
connection cap), ``guard`` (the wslink hello and the calls a page may make), ``budget`` (the
memory caps of chunked messages) and ``client_values`` (what a page may write); ``connections``
the guarded listening sites (idle and partial connections, connections per address); ``sync``
the per-page state synchronisation that replaces trame's; ``versions`` the framework releases
the patches were checked against, and the check made at start (the standard library and
``packaging`` only: this package's ``__init__`` imports nothing, so that the check runs before any
patch is loaded).
"""
