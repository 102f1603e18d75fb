"""systemd notification (sd_notify) for Type=notify services with a watchdog.

Writes ``READY=1``, ``WATCHDOG=1``, ``STATUS=...`` and ``STOPPING=1`` to the
datagram socket systemd names in ``$NOTIFY_SOCKET``; does nothing when the
service is not run by systemd. The protocol is one datagram of text
(sd_notify(3)); a dozen lines here spare a dependency on libsystemd.
"""

from __future__ import annotations

import logging
import os
import socket

log = logging.getLogger(__name__)


class SystemdNotifier:
    """Send sd_notify messages when ``$NOTIFY_SOCKET`` is set."""

    def __init__(self) -> None:
        address = os.environ.get("NOTIFY_SOCKET", "")
        if address.startswith("@"):
            address = "\0" + address[1:]
        self._address = address
        self._sock: socket.socket | None = None
        if address:
            self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        usec = os.environ.get("WATCHDOG_USEC", "")
        self.watchdog_period_s: float | None = int(usec) / 1e6 if usec.isdigit() else None
        """The watchdog timeout systemd set (WatchdogSec), or None."""

    @property
    def enabled(self) -> bool:
        """True when running under systemd with a notify socket."""
        return self._sock is not None

    def notify(self, state: str) -> None:
        """Send one notification; failures are logged, never raised."""
        if self._sock is None:
            return
        try:
            self._sock.sendto(state.encode(), self._address)
        except OSError as exc:
            log.warning("sd_notify %r failed: %s", state, exc)
