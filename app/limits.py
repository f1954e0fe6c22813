"""A cap on the size of one websocket message from a client.

wslink (trame's transport) lets an authenticated client send messages of up to 4 GB, reassembled
in memory from chunks, and trame's client secret is public: any page could make the server
allocate gigabytes. ``cap_websocket_messages`` lowers that limit for every connection; a larger
message raises in wslink and that connection is dropped. The page's largest message is a mesh
upload, itself capped at ``app.logic.upload.MAX_UPLOAD_BYTES``.
"""

from __future__ import annotations

from app.logic.upload import MAX_UPLOAD_BYTES

MAX_MESSAGE_BYTES = MAX_UPLOAD_BYTES + 16 * 2**20  # an upload plus its envelope, with margin


def cap_websocket_messages(limit: int = MAX_MESSAGE_BYTES) -> None:
    """Make wslink's un-chunker refuse client messages over ``limit`` bytes (idempotent)."""
    from wslink import chunking

    unchunker = chunking.UnChunker
    original = getattr(unchunker.set_max_message_size, "__wrapped__", None)
    original = original or unchunker.set_max_message_size

    def set_max_message_size(self, size: int) -> None:
        original(self, min(int(size), limit))

    set_max_message_size.__wrapped__ = original  # type: ignore[attr-defined]
    unchunker.set_max_message_size = set_max_message_size
