"""A device simulator on a pseudo-terminal: the driver opens the slave side by path with
pyserial exactly as it would open /dev/ttyUSB0, the simulator answers on the master side.

The port path is a symlink in a temporary folder that stays the same when the simulator is
"unplugged" (both sides closed: the driver's next read fails with EIO, as a pulled USB-serial
adapter does) and "plugged back" (a new pseudo-terminal behind the same path)."""

import errno
import os
import select
import shutil
import tempfile
import threading
import time

from .device import DeviceError


class PtySimulator:
    """Subclasses implement `on_bytes(data)` (commands from the host) and `tick(now)` (called at
    `rate` ticks per second of simulated time while `streaming`); they write with `send()`.

    `speed` > 1 runs the device clock faster than real time (ticks are `1/rate` of device time
    apart, `1/(rate*speed)` of wall time)."""

    def __init__(self, name="sim", rate=100.0, speed=1.0):
        self.rate = float(rate)
        self.speed = float(speed)
        self.streaming = False
        self._dir = tempfile.mkdtemp(prefix="humananim-sim-")
        self.port = os.path.join(self._dir, name)
        self._master = self._slave = None
        self._lock = threading.Lock()
        self._thread = None
        self._running = False
        self.sent_bytes = 0
        self.dropped_bytes = 0
        self._cut = 0
        self._plug()

    # -- the line ------------------------------------------------------------------------
    def _plug(self):
        if not hasattr(os, "openpty"):
            raise DeviceError("the device simulators need a pseudo-terminal (Linux or macOS); on Windows "
                              "use a real port or a null-modem pair (com0com)")
        import tty  # POSIX only: imported here so the drivers still load on Windows
        master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no CR/LF translation, ^C is a byte, not a signal
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        tmp = self.port + ".new"
        if os.path.lexists(tmp):
            os.unlink(tmp)
        os.symlink(os.ttyname(slave), tmp)
        os.replace(tmp, self.port)

    def unplug(self):
        """The cable is pulled: the driver's reads fail, the port path disappears."""
        with self._lock:
            self.streaming = False
            for fd in (self._master, self._slave):
                if fd is not None:
                    os.close(fd)
            self._master = self._slave = None
            if os.path.lexists(self.port):
                os.unlink(self.port)

    def replug(self):
        with self._lock:
            if self._master is None:
                self._plug()
                self.on_power_up()

    @property
    def plugged(self):
        return self._master is not None

    def inject(self, data):
        """Bytes on the line that the device did not send (noise, another program)."""
        with self._lock:
            self.send(bytes(data))

    def cut(self, n):
        """The next n bytes the device sends are lost on the line."""
        with self._lock:
            self._cut += int(n)

    def power_cycle(self):
        """The device is switched off and on: its power-up state, the line kept."""
        with self._lock:
            self.on_power_up()

    def send(self, data):
        """Write to the host; bytes nobody reads are lost, as on a real line (never blocks)."""
        if self._cut and data:
            k = min(self._cut, len(data))
            self._cut -= k
            data = data[k:]
        if self._master is None or not data:
            return
        try:
            n = os.write(self._master, data)
            self.sent_bytes += n
            if n < len(data):
                self.dropped_bytes += len(data) - n
        except OSError as exc:
            if exc.errno in (errno.EAGAIN, errno.EWOULDBLOCK, errno.EIO):
                self.dropped_bytes += len(data)
            else:
                raise

    # -- the loop --------------------------------------------------------------------------
    def start(self):
        self._running = True
        self._thread = threading.Thread(target=self._loop, name="humananim-sim", daemon=True)
        self._thread.start()
        return self

    def stop(self):
        self._running = False
        if self._thread is not None:
            self._thread.join(2.0)
        self.unplug()
        shutil.rmtree(self._dir, ignore_errors=True)

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()

    def _loop(self):
        period = 1.0 / (self.rate * self.speed)
        next_tick = time.perf_counter()
        while self._running:
            now = time.perf_counter()
            if self.streaming and now >= next_tick:
                with self._lock:
                    if self.streaming:
                        self.tick(now)
                next_tick += period
                if next_tick < now - 0.5:  # far behind (machine stalled): don't burst forever
                    next_tick = now
                continue
            if not self.streaming:
                next_tick = now
            wait = max(0.0, min(next_tick - now, 0.005)) if self.streaming else 0.005
            master = self._master
            if master is None:
                time.sleep(wait or 0.005)
                continue
            try:
                ready, _, _ = select.select([master], [], [], wait)
            except (OSError, ValueError):
                continue
            if ready:
                try:
                    data = os.read(master, 4096)
                except OSError:
                    data = b""
                if data:
                    with self._lock:
                        self.on_bytes(data)

    # -- the device's part --------------------------------------------------------------------
    def on_bytes(self, data):
        raise NotImplementedError

    def tick(self, now):
        raise NotImplementedError

    def on_power_up(self):
        """A replugged device starts in its power-up state."""
        self.streaming = False
