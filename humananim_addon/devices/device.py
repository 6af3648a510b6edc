"""The device base: one reader thread per device, samples into a bounded ring buffer,
status for the panel, and reconnection when an unplugged device comes back.

A driver subclass implements `_open()`, `_read()` (returns decoded samples; may block for at
most its own timeout) and `_close()`. Any exception from them marks the device
'disconnected' and the thread retries `_open()` every `reconnect_interval` seconds, so a
replugged device resumes on its own. Decoding trouble (garbage on the line) is reported by
the driver through `self.resyncing`, shown as status 'resyncing'."""

import collections
import socket
import threading
import time

from ...solver.errors import HumanAnimError
from .ringbuffer import RingBuffer
from .samples import Sample

STATUSES = ("stopped", "connecting", "connected", "resyncing", "disconnected")


class DeviceError(HumanAnimError):
    """A device cannot be opened or spoke something we cannot use."""


class Device:
    kind = "device"

    def __init__(self, name, capacity=8192, reconnect_interval=0.5):
        self.name = name
        self.buffer = RingBuffer(capacity)
        self.reconnect_interval = reconnect_interval
        self.status = "stopped"
        self.last_error = ""
        self.resyncing = False
        self.silent = False  # a listening device (UDP) hears nothing: shown as 'disconnected'
        # honest counters, kept apart: records known lost (a gap the protocol shows: a bird
        # missing from a group-mode tick, a sample counter or time stamp that skipped), bytes
        # discarded while finding records, and how many times the stream lost its framing
        self.lost = 0
        self.discarded_bytes = 0
        self.resyncs = 0
        self.reconnects = 0
        self.seq = 0
        self._times = collections.deque(maxlen=1024)
        self._channels = set()
        self._thread = None
        self._stop = threading.Event()
        self._opened = False

    # -- the driver's part -------------------------------------------------------------
    def _open(self):
        raise NotImplementedError

    def _read(self):
        raise NotImplementedError

    def _close(self):
        pass

    # -- lifecycle -------------------------------------------------------------------
    def start(self):
        if self._thread is not None and self._thread.is_alive():
            return
        self._stop.clear()
        self.status = "connecting"
        self._thread = threading.Thread(target=self._run, name=f"humananim-capture-{self.name}", daemon=True)
        self._thread.start()

    def stop(self, timeout=2.0):
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)
            self._thread = None
        self._safe_close()
        self.status = "stopped"

    @property
    def running(self):
        return self._thread is not None and self._thread.is_alive()

    def _run(self):
        first = True
        while not self._stop.is_set():
            if not self._opened:
                try:
                    self._open()
                    self._opened = True
                    if not first:
                        self.reconnects += 1
                    first = False
                    self.status = "connected"
                    self.last_error = ""
                except Exception as exc:  # a device that is not there yet: retry
                    self._fault(exc)
                    self._stop.wait(self.reconnect_interval)
                    continue
            try:
                samples = self._read()
            except Exception as exc:
                self._fault(exc)
                self._safe_close()
                self._stop.wait(self.reconnect_interval)
                continue
            self.buffer.push_many(samples)
            for s in samples:
                self._times.append(s.time)
                self._channels.add(s.channel)
            self.status = "disconnected" if self.silent else "resyncing" if self.resyncing else "connected"

    def _fault(self, exc):
        self.status = "disconnected"
        self.last_error = f"{type(exc).__name__}: {exc}" if not isinstance(exc, HumanAnimError) else str(exc)

    def _safe_close(self):
        if self._opened:
            self._opened = False
            try:
                self._close()
            except Exception:
                pass

    # -- helpers for drivers -----------------------------------------------------------
    def _read_stream(self, whole=None):
        """Bytes of a serial device in stream mode: wait for the rest of what the device sends
        at once (`whole` bytes, default one record), not byte by byte: one wake-up per tick."""
        whole = whole or self._parser.size
        return self._ser.read(max(self._ser.in_waiting, whole - len(self._parser.buf), 1))

    def _records(self, data, now):
        """The records in `data` by the device's parser, its resync counters updated; None on
        silence, a DeviceError after `watchdog` seconds of it."""
        if not data:
            if now - self._last_data > self.watchdog:
                raise DeviceError(f"{self.name}: no data for {self.watchdog:g} s")
            return None
        self._last_data = now
        records = self._parser.feed(data)
        self.discarded_bytes, self.resyncs = self._parser.discarded_bytes, self._parser.resyncs
        self.resyncing = self._parser.resyncing
        return records

    def make_sample(self, channel, kind, data, t=None):
        self.seq += 1
        return Sample(self.name, channel, self.seq, time.perf_counter() if t is None else t, kind, data)

    # -- what the panel shows ------------------------------------------------------------
    def measured_rate(self, window=1.0):
        """Samples per second (all channels) over the last `window` seconds of received samples;
        the status shows it per channel (per bird)."""
        times = list(self._times)
        if len(times) < 2:
            return 0.0
        recent = [t for t in times if t >= times[-1] - window]
        if len(recent) < 2 or recent[-1] <= recent[0]:
            return 0.0
        return (len(recent) - 1) / (recent[-1] - recent[0])

    def _new_parser(self, parser):
        """A fresh parser on (re)connect: its counters continue the device's."""
        parser.discarded_bytes, parser.resyncs = self.discarded_bytes, self.resyncs
        return parser

    @property
    def dropped(self):
        """Samples lost: records known lost on the line plus samples the session did not drain
        in time (the ring buffer overwrote them)."""
        return self.buffer.dropped + self.lost

    def status_dict(self):
        return {"name": self.name, "kind": self.kind, "status": self.status,
                "rate_hz": round(self.measured_rate() / max(1, len(self._channels)), 2),
                "channels": len(self._channels), "samples": self.seq, "dropped": self.dropped,
                "lost": self.lost, "overwritten": self.buffer.dropped, "discarded_bytes": self.discarded_bytes,
                "resyncs": self.resyncs, "reconnects": self.reconnects,
                "last_error": self.last_error}


class DatagramDevice(Device):
    """A device that listens for UDP datagrams on host:port (VMC, Xsens MVN). Silence for
    `watchdog` seconds shows 'disconnected' (a sender cannot be told from a pulled cable); when
    datagrams come back that counts as a reconnection. Subclasses implement `_datagram(data,
    now)` returning samples."""

    what = "datagrams"

    def __init__(self, name, host, port, timeout=0.05, watchdog=1.0, **kw):
        super().__init__(name, **kw)
        self.host, self.port, self.timeout, self.watchdog = host, int(port), timeout, watchdog
        self._sock = None
        self._last = 0.0

    def _open(self):
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 21)
        try:
            sock.bind((self.host, self.port))
        except OSError as exc:
            sock.close()
            raise DeviceError(f"{self.name}: cannot listen on {self.host}:{self.port} ({exc.strerror})") from None
        sock.settimeout(self.timeout)
        self._sock = sock
        self._last = time.perf_counter()

    @property
    def bound_port(self):
        return self._sock.getsockname()[1] if self._sock is not None else None

    def _read(self):
        try:
            data = self._sock.recv(65536)
        except socket.timeout:
            data = None
        now = time.perf_counter()
        if not data:
            if now - self._last > self.watchdog and not self.silent:
                self.silent = True
                self.last_error = f"no {self.what} for {self.watchdog:g} s"
            return []
        if self.silent:
            self.silent = False
            self.reconnects += 1
        self._last = now
        return self._datagram(data, now)

    def _datagram(self, data, now):
        raise NotImplementedError

    def _close(self):
        sock, self._sock = self._sock, None
        if sock is not None:
            sock.close()


def open_serial(port, baud, timeout):
    """A pyserial port, with a clear message when pyserial is missing."""
    try:
        import serial
    except ImportError:
        raise DeviceError("pyserial is not installed: serial devices (Flock of Birds, CyberGlove) "
                          "need it (pip install pyserial)") from None
    return serial.Serial(port, baudrate=baud, timeout=timeout, write_timeout=1.0)
