"""Where the live sentences go: serial ports, UDP, a TCP server — each on its own thread behind a bounded queue.

The engine calls :meth:`Output.send` (never blocks: when the queue is full the line is dropped and counted).
The writer thread drains the queue; a serial port that blocks or a TCP client that stops reading stalls only
its own thread (a TCP client has its own queue and socket; when its queue is full its lines are dropped and
counted, and a client that cannot take anything for ``client_timeout_s`` is closed). URLs:

- ``udp://HOST:PORT`` — one datagram per line (broadcast when HOST is a broadcast address such as
  255.255.255.255 or x.y.z.255);
- ``tcp://[HOST]:PORT`` — a server; any number of clients; HOST defaults to 127.0.0.1 (loopback: say
  ``tcp://0.0.0.0:PORT`` to serve the network);
- ``serial:///dev/ttyX?baud=N`` — RS-232/422 at N baud (default 4800, 38400 for high rates).
"""

from __future__ import annotations

import collections
import os
import queue
import select
import socket
import threading
import time
from typing import Any
from urllib.parse import parse_qs, urlparse

from formats.errors import ImutoolError

QUEUE_LINES = 256  # blocks of sentences an output (or a TCP client) may hold before it drops
CLIENT_SNDBUF = 65536  # bytes of a TCP client's kernel send buffer (~10 s of sentences at 10 Hz)


class Output:
    """A destination with a bounded queue drained by its own thread."""

    kind = "output"

    def __init__(self, url: str, maxsize: int = QUEUE_LINES) -> None:
        self.url = url
        self.q: collections.deque[bytes | None] = collections.deque()
        self.maxsize = maxsize
        self.sent = 0
        self.dropped = 0
        self.errors = 0
        self._stop = threading.Event()
        self._wake = threading.Event()  # set by send() when the writer waits on an empty queue
        self._idle = False
        self._thread = threading.Thread(target=self._run, name=f"live-out {url}", daemon=True)

    def start(self) -> Output:
        self._thread.start()
        return self

    def send(self, data: bytes) -> None:
        """Queue ``data`` (one or more CRLF-ended lines); dropped and counted when the queue is full. The writer is
        woken only when it sleeps on an empty queue (one event per burst, not per line; never blocks here)."""
        if len(self.q) >= self.maxsize:
            self.dropped += 1
        else:
            self.q.append(data)
            if self._idle:
                self._wake.set()

    def _get(self, timeout: float) -> bytes | None:
        """The next queued item, waiting up to ``timeout`` s for one; b'' when none came."""
        try:
            return self.q.popleft()
        except IndexError:
            pass
        self._wake.clear()
        self._idle = True
        try:
            try:  # queued between the first look and the flag: taken without sleeping
                return self.q.popleft()
            except IndexError:
                pass
            if not self._stop.is_set():
                self._wake.wait(timeout)
        finally:
            self._idle = False
        try:
            return self.q.popleft()
        except IndexError:
            return b""

    def _run(self) -> None:
        while True:
            data = self._get(0.2)
            if data is None:
                break
            if not data:
                if self._stop.is_set():
                    break
                continue
            try:
                self.write(data)
                self.sent += 1
            except OSError:
                self.errors += 1

    def write(self, data: bytes) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def close(self, timeout: float = 1.0) -> None:
        """Flush what is queued (up to ``timeout`` s), then close."""
        self.q.append(None)
        self._wake.set()
        self._thread.join(timeout)
        self._stop.set()
        self._close()

    def _close(self) -> None:
        pass

    def stats(self) -> dict[str, Any]:
        return {"url": self.url, "sent": self.sent, "dropped": self.dropped, "errors": self.errors}


class UdpOutput(Output):
    kind = "udp"

    def __init__(self, url: str, host: str, port: int) -> None:
        super().__init__(url)
        self.addr = (host, port)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        if host == "255.255.255.255" or host.endswith(".255"):
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)

    def write(self, data: bytes) -> None:
        for line in data.splitlines(keepends=True):
            self.sock.sendto(line, self.addr)

    def _close(self) -> None:
        self.sock.close()


class _Client:
    def __init__(self, sock: socket.socket, addr: Any, maxsize: int) -> None:
        self.sock, self.addr = sock, addr
        self.q: queue.Queue[bytes] = queue.Queue(maxsize)
        self.pending = b""
        self.dropped = 0
        self.stuck_since: float | None = None


class TcpServerOutput(Output):
    """A TCP server: every client gets every line; a slow client loses lines (counted), never the others."""

    kind = "tcp"

    def __init__(self, url: str, host: str, port: int, client_timeout_s: float = 30.0) -> None:
        super().__init__(url)
        self.srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self.srv.bind((host, port))
        except OSError as e:
            raise ImutoolError(f"cannot listen on {host}:{port}: {e.strerror}", path=url) from None
        self.srv.listen(16)
        self.srv.setblocking(False)
        self.port = self.srv.getsockname()[1]
        self.clients: list[_Client] = []
        self.client_timeout_s = client_timeout_s
        self.clients_seen = 0
        self.clients_dropped_lines = 0
        self.clients_closed_stuck = 0

    def _run(self) -> None:  # one thread: accept, fan out, write without blocking
        while not self._stop.is_set():
            data = self._get(0.02)
            if data is None:
                self._pump(final=True)
                break
            self._accept()
            if data:
                self.sent += 1
                for c in self.clients:
                    try:
                        c.q.put_nowait(data)
                    except queue.Full:
                        c.dropped += 1
                        self.clients_dropped_lines += 1
            self._pump()

    def _accept(self) -> None:
        while True:
            try:
                s, addr = self.srv.accept()
            except (BlockingIOError, OSError):
                return
            s.setblocking(False)
            s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, CLIENT_SNDBUF)  # a slow client holds little
            self.clients.append(_Client(s, addr, QUEUE_LINES))
            self.clients_seen += 1

    def _pump(self, final: bool = False) -> None:
        now = time.monotonic()
        for c in list(self.clients):
            try:
                while True:
                    if not c.pending:
                        try:
                            c.pending = c.q.get_nowait()
                        except queue.Empty:
                            break
                    n = c.sock.send(c.pending)
                    c.pending = c.pending[n:]
                    if c.pending:
                        break
                c.stuck_since = None if not c.pending else (c.stuck_since or now)
                if c.stuck_since is not None and now - c.stuck_since > self.client_timeout_s:
                    self.clients_closed_stuck += 1
                    raise OSError("client stopped reading")
                r, _, _ = select.select([c.sock], [], [], 0)
                if r and not c.sock.recv(4096):  # the client closed
                    raise OSError("closed")
            except BlockingIOError:
                c.stuck_since = c.stuck_since or now
            except OSError:
                c.sock.close()
                self.clients.remove(c)

    def _close(self) -> None:
        for c in self.clients:
            c.sock.close()
        self.srv.close()

    def stats(self) -> dict[str, Any]:
        out = super().stats()
        out.update(
            clients=len(self.clients),
            clients_seen=self.clients_seen,
            client_dropped=self.clients_dropped_lines,
            clients_closed_stuck=self.clients_closed_stuck,
        )
        return out


class SerialOutput(Output):
    """A serial port (RS-232/422) at ``baud``; a port that blocks fills the queue and lines are dropped."""

    kind = "serial"

    def __init__(self, url: str, path: str, baud: int) -> None:
        super().__init__(url)
        self.path, self.baud = path, baud
        self.fd = self._open()

    def _open(self) -> int:
        import termios

        try:
            fd = os.open(self.path, os.O_WRONLY | os.O_NOCTTY)
        except OSError as e:
            raise ImutoolError(f"cannot open the output port: {e.strerror}", path=self.path) from None
        try:
            attrs = termios.tcgetattr(fd)
            speed = getattr(termios, f"B{self.baud}", None)
            if speed is None:
                raise ImutoolError(f"baud {self.baud} is not a standard rate", path=self.path)
            attrs[0] = 0  # raw: no input processing
            attrs[1] = 0  # no output processing (CR/LF sent as they are)
            attrs[2] = termios.CS8 | termios.CREAD | termios.CLOCAL
            attrs[3] = 0
            attrs[4] = attrs[5] = speed
            termios.tcsetattr(fd, termios.TCSANOW, attrs)
        except termios.error:
            pass  # not a terminal (a FIFO or file in a test): written as it is
        return fd

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            n = os.write(self.fd, view)
            view = view[n:]

    def _close(self) -> None:
        try:
            os.close(self.fd)
        except OSError:
            pass


def open_output(url: str) -> Output:
    """An output from its URL (see the module docstring), started."""
    u = urlparse(url)
    try:
        if u.scheme == "udp":
            if not u.hostname or not u.port:
                raise ValueError
            return UdpOutput(url, u.hostname, u.port).start()
        if u.scheme == "tcp":
            if u.port is None:
                raise ValueError
            return TcpServerOutput(url, u.hostname or "127.0.0.1", u.port).start()
        if u.scheme == "serial":
            baud = int(parse_qs(u.query).get("baud", ["4800"])[0])
            if not u.path:
                raise ValueError
            return SerialOutput(url, u.path, baud).start()
    except ValueError:
        pass
    raise ImutoolError(f"output {url!r}: expected udp://HOST:PORT, tcp://[HOST]:PORT or serial:///dev/ttyX?baud=N")
