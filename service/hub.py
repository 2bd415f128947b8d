"""Fan-out of messages from the pipeline thread to WebSocket clients.

Each client has two slots, one for a pending state and one for a pending parameter message: a
newer message replaces an older one of its kind that the client has not taken yet (counted as
dropped), so a stalled client only ever gets the newest of each and never holds up the pipeline
or the other clients. A client that keeps up gets every message. A parameter message carries the
whole parameters, so the newest one is all a client needs; the patches of the versions it missed
are in ``GET /api/v1/params/history``. The parameter message goes out before the state.
"""

from __future__ import annotations

import asyncio
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field


@dataclass
class Message:
    """One outgoing message, serialised once: ``plain`` (state line) and ``with_points``."""

    kind: str  # "state" or "params"
    plain: str
    with_points: str | None = None


@dataclass(eq=False)
class Client:
    want_points: bool
    state: Message | None = None
    params: Message | None = None
    dropped: int = 0  # states replaced before the client took them
    params_dropped: int = 0  # parameter messages replaced before the client took them
    sent: int = 0
    wake: asyncio.Event = field(default_factory=asyncio.Event)

    def offer(self, message: Message) -> bool:
        """Store a message for this client; True if an untaken one of its kind was replaced."""
        if message.kind == "state":
            replaced = self.state is not None
            self.dropped += replaced
            self.state = message
        else:
            replaced = self.params is not None
            self.params_dropped += replaced
            self.params = message
        self.wake.set()
        return replaced

    async def next_text(self) -> str:
        """The next message to send (a parameter message first), waiting if there is none."""
        while True:
            if self.params is not None:
                message, self.params = self.params, None
                return self._text(message)
            if self.state is not None:
                message, self.state = self.state, None
                return self._text(message)
            self.wake.clear()
            await self.wake.wait()

    def _text(self, message: Message) -> str:
        if self.want_points and message.with_points is not None:
            return message.with_points
        return message.plain


DELIVERY_WINDOW = 100


class Hub:
    """Thread-safe ``publish`` from any thread; clients live on one asyncio loop."""

    def __init__(self, on_drop: Callable[[], None] | None = None, on_count: Callable[[int], None] | None = None):
        self._clients: set[Client] = set()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._lock = threading.Lock()
        self.on_drop = on_drop
        self.on_count = on_count
        self._deliveries: deque = deque(maxlen=DELIVERY_WINDOW)  # (clients offered, of them replaced)

    def bind(self, loop: asyncio.AbstractEventLoop) -> None:
        with self._lock:
            self._loop = loop

    def unbind(self) -> None:
        with self._lock:
            self._loop = None

    @property
    def client_count(self) -> int:
        return len(self._clients)

    def stats(self) -> list[dict]:
        """Per connected client: messages sent, states and parameter messages replaced before it took them."""
        return [
            {"sent": c.sent, "dropped": c.dropped, "params_dropped": c.params_dropped, "points": c.want_points}
            for c in list(self._clients)
        ]

    def add(self, want_points: bool) -> Client:
        client = Client(want_points=want_points)
        self._clients.add(client)
        self._counted()
        return client

    def remove(self, client: Client) -> None:
        self._clients.discard(client)
        self._counted()

    def publish(self, message: Message) -> None:
        """Called from the pipeline thread: never blocks on clients."""
        with self._lock:
            loop = self._loop
            if loop is None or loop.is_closed():
                return
            try:
                loop.call_soon_threadsafe(self._deliver, message)
            except RuntimeError:  # loop shutting down
                pass

    def _deliver(self, message: Message) -> None:
        clients = list(self._clients)
        replaced = 0
        for client in clients:
            if client.offer(message):
                replaced += 1
                if self.on_drop is not None:
                    self.on_drop()
        if clients:
            self._deliveries.append((len(clients), replaced))

    def drop_rate(self) -> float:
        """Share of the messages of the last DELIVERY_WINDOW deliveries replaced before a client took them."""
        deliveries = list(self._deliveries)
        offered = sum(n for n, _ in deliveries)
        return sum(r for _, r in deliveries) / offered if offered else 0.0

    def _counted(self) -> None:
        if self.on_count is not None:
            self.on_count(len(self._clients))
