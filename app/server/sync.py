"""The shared state between the server and its pages: only declared keys from a client, the last
write wins on every page.

trame (trame-server 4.1.0) applies a client's state update like this: it forwards the raw values at
once to "every client but the last active one", then stores them, then runs the change callbacks,
whose corrections follow. Three pages changing sliders at once ended with values none of them set
last:

* the trame page keeps a changed value "dirty" until its previous call is answered and then sends
  the value it holds *at that moment*; a value forwarded from another page in between overwrites
  the unsent one, so the page sends the other page's (older) value back as its own, after the
  newer ones;
* "the last active client" is read when the forward is sent, not when the update arrived: with
  several pages busy it can be another page, which then misses the change (and the sender gets an
  echo), while trame's one cache for all pages believes every page has it.

:class:`ClientStateSync` replaces the forward and that cache (the methods ``push_state_change``
and ``clear_state_client_cache`` of trame's protocol instance, see ``attach``):

* a client may write only the keys the app declares for it, each value through its screen;
  anything else is dropped and logged, never stored or forwarded (a key with a refusal hook,
  such as an upload's, also tells the page why: ``refusals``);
* each page has its own record of what it was sent; a value reaches a page only if it differs
  from that record, and only once the change callbacks have run (a value the controls' validators
  correct is never forwarded raw, and an upload's bytes never leave the server);
* a page that sends, for a key, a value the server pushed to it since it last sent that key is
  echoing a push that overwrote its own unsent change (see above): that write is dropped and the
  page is sent the current value, so the last genuine write wins and every page ends showing it
  (a page that really chose such a value again sees it replaced by the current one);
* a page's state update is answered only after the values it caused have been sent to that page
  (``busy``, a correction): wslink's publish sends on a later turn of the event loop, after an
  answer sent at once, so a page that read "my change is answered" as "the server's state is
  here" took the old, idle state for the final one. The Guard sends the pushes at once, in order,
  and waits for those of the page before answering it (``send``).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping
from typing import Any

import msgpack
from trame_server.utils import clean_state

from app.state import echo

log = logging.getLogger(__name__)

STATE_TOPIC = "trame.state.topic"
MAX_REMEMBERED = 16  # values pushed to a page per key, remembered to recognise its echoes


class ClientStateSync:
    """Per-page state synchronisation for one trame server (see the module docstring)."""

    def __init__(self, state, screens: Mapping[str, Callable[[Any], Any]]):
        self.state = state
        self.screens = dict(screens)
        self.protocol = None
        self.clients: Callable[[], list[str]] = list  # set by app.server.guard.Guard
        # sends one page a push at once (set by the Guard, see Guard.send_state); else wslink's
        # publish, which sends it on a later turn of the event loop
        self.send: Callable[[str, dict], None] | None = None
        self._sent: dict[str, dict[str, bytes]] = {}  # page -> key -> packed value it holds
        # page -> client key -> values pushed to it since it last sent that key (the newest few)
        self._pushed: dict[str, dict[str, list[bytes]]] = {}
        self._held: set[str] = set()  # keys of a client update being applied
        # key -> called with a client's value its screen refused, to tell the page why (a value
        # of no other key is only logged)
        self.refusals: dict[str, Callable[[Any], None]] = {}
        self.n_dropped = 0
        self.n_echoes = 0
        # when a page last changed the scene (a value it set that differs from the one held, or
        # a trigger whose run changed the state): a session's use, as its reaper counts it
        self.last_change_s = time.monotonic()
        self.n_pushed_keys = 0  # state keys pushed so far (a trigger's effect is seen by it)

    def attach(self, protocol) -> None:
        """Take over trame's state push on its protocol instance (trame-server 4.1.0)."""
        self.protocol = protocol
        protocol.push_state_change = self.push_state_change
        protocol.clear_state_client_cache = self.clear

    def forget(self, client_id: str) -> None:
        self._sent.pop(client_id, None)
        self._pushed.pop(client_id, None)

    def clear(self, *keys: str) -> None:
        """Forget what the pages hold for ``keys``: their next push goes to every page."""
        for sent in self._sent.values():
            for key in keys:
                sent.pop(key, None)

    # -- server -> pages ---------------------------------------------------------------------------
    def push_state_change(self, modified_state: dict, skip_last_active_client: bool = False):
        """Send each page the modified values it does not hold yet (held keys wait)."""
        values, packed = clean_state(modified_state)
        keys = [k for k in values if k not in self._held]
        self.n_pushed_keys += len(keys)
        for client_id in self.clients():
            sent = self._sent.setdefault(client_id, {})
            update = {k: values[k] for k in keys if sent.get(k) != packed[k]}
            if not update:
                continue
            pushed = self._pushed.setdefault(client_id, {})
            for key in update:
                sent[key] = packed[key]
                if key in self.screens:
                    remembered = pushed.setdefault(key, [])
                    remembered.append(packed[key])
                    del remembered[:-MAX_REMEMBERED]
            if self.send is not None:
                self.send(client_id, update)
            else:
                self.protocol.publish(STATE_TOPIC, update, client_id=client_id)

    # -- page -> server ----------------------------------------------------------------------------
    def apply_client_changes(self, client_id: str, changes: list[tuple[str, Any]]) -> dict:
        """Store the accepted ``(key, value)`` changes of one page, run the change callbacks, then
        send the resulting values to the pages that do not hold them. Returns what was accepted."""
        accepted, echoes = self._accept(client_id, changes)
        if any(self.state[key] != value for key, value in accepted.items()):
            self.last_change_s = time.monotonic()
        held = set(accepted) - self._held
        self._held |= held
        try:
            if accepted:
                with self.state:
                    self.state.update(accepted)
        finally:
            self._held -= held
        resync = [*accepted, *echoes]
        if resync:
            self.push_state_change({key: self.state[key] for key in resync})
        return accepted

    def _accept(self, client_id: str, changes: list[tuple[str, Any]]) -> tuple[dict, list[str]]:
        """The changes to store, and the keys of the page's echoes (it holds those values)."""
        sent = self._sent.setdefault(client_id, {})
        pushed = self._pushed.setdefault(client_id, {})
        accepted: dict[str, Any] = {}
        echoes: list[str] = []
        for key, raw in changes:
            screen = self.screens.get(key)
            try:
                if screen is None:
                    raise ValueError("not a key a client may set")
                value = screen(raw)
                packed = msgpack.packb(value)
            except (ValueError, TypeError, OverflowError) as exc:
                self.n_dropped += 1
                log.warning("dropped state %s from a client: %s", echo(key), str(exc)[:200])
                if key in self.refusals:
                    with self.state:  # sent now (a state.update alone waits for a flush)
                        self.refusals[key](raw)
                continue
            sent[key] = packed  # what the page holds now
            if packed in pushed.get(key, ()):
                self.n_echoes += 1  # the page sent back what we pushed over its unsent change
                echoes.append(key)
                continue
            pushed.pop(key, None)
            accepted[key] = value
        return accepted, echoes
