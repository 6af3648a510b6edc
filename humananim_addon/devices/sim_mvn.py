"""An Xsens MVN network streamer (the sending side), written from the "MVN real-time network
streaming Protocol Specification" (revision N) and independently of the receiver in mvn.py (it
imports nothing from it).

It sends, to host:port over UDP, per sample and per actor: pose datagrams of type 02
(2.5.3: segment ID i32, position x, y, z in cm, quaternion q1 re, q2 i, q3 j, q4 k as big-endian
floats; 23 body segments, then props, then finger segments, 2.5.1) behind the 24-byte header
(2.4.1), split over several datagrams when `max_items` is smaller than the sample (datagram
counter index, bit 7 on the last, 2.4.1.3); meta data (type 12, 2.6.1) every `meta_every`
samples; the quaternion's sign alternates (the specification promises it normalised, not
positive). Faults for tests and the soak: drop, duplicate, reorder, garbage, other message
types, silence and a restarted sample counter."""

import socket
import struct
import threading
import time

import numpy as np

_HEADER = ">6sIBBIBBBBHH"  # reserved sent as one u16 0
_ITEM = np.dtype([("id", ">i4"), ("values", ">f4", (7,))])  # 2.5.3: segment ID, x, y, z, q1-q4


def default_segment_motion(actor, segment_id, t):
    """Position (cm) and unit quaternion (w, x, y, z) of a segment at device time t; segment_id
    or t may be arrays (n,): then (3, n) and (4, n)."""
    t = np.asarray(t, float)
    k = segment_id + 7 * actor
    pos = np.stack([100 * np.sin(0.3 * t + k) + 50 * actor + 0 * t, 60 * np.cos(0.2 * t + 0.5 * k),
                    5 * k + 10 * np.sin(t)])
    axis = np.stack([np.sin(0.5 * t + k), np.cos(0.4 * t + 2 * k), 0.5 + np.sin(0.7 * t + 0.3 * k)])
    axis = axis / np.linalg.norm(axis, axis=0)
    angle = 2.5 * np.sin(0.6 * t + k)
    return pos, np.concatenate([np.cos(angle / 2)[None], np.sin(angle / 2) * axis])


class MVNSender:
    def __init__(self, port, host="127.0.0.1", actors=(0,), rate=60.0, speed=1.0, props=0, fingers=0,
                 max_items=None, meta_every=60, motion=default_segment_motion, names=None):
        self.address = (host, int(port))
        self.actors, self.rate, self.speed = tuple(actors), float(rate), float(speed)
        self.props, self.fingers = props, fingers
        self.max_items, self.meta_every, self.motion = max_items, meta_every, motion
        self.names = names or {a: f"Actor {chr(65 + a)}" for a in self.actors}
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.counters = {a: 0 for a in self.actors}
        self.sent = {}  # (actor, sample counter) -> (tick, perf_counter when sent)
        self.tick_count = 0
        self.paused = False
        self.datagrams = 0
        self._lock = threading.Lock()
        self._faults = []  # pending one-shot faults
        self._held = None
        self._thread = None
        self._running = False

    # -- the data ---------------------------------------------------------------------------
    def segment_ids(self):
        ids = list(range(1, 24)) + list(range(24, 24 + self.props))
        return ids + [24 + self.props + k for k in range(self.fingers)]  # finger IDs: index + 1 (3.1)

    def true_pose(self, actor, segment_id, tick):
        """The pose a sample carries: position in metres, quaternion (w, x, y, z)."""
        pos, q = self.motion(actor, segment_id, tick / self.rate)
        return np.asarray(pos, float) / 100.0, np.asarray(q, float)

    def datagrams_of(self, actor, tick, counter):
        ids = np.array(self.segment_ids())
        pos, q = self.motion(actor, ids, tick / self.rate)  # every segment at once: (3, n), (4, n)
        items = np.zeros(len(ids), dtype=_ITEM)
        items["id"] = ids
        items["values"][:, :3] = np.asarray(pos, float).T
        items["values"][:, 3:] = np.asarray(q, float).T * np.where((tick + ids) % 2, -1.0, 1.0)[:, None]
        per = self.max_items or len(items)
        chunks = [items[i:i + per] for i in range(0, len(items), per)]
        out = []
        time_code = int(round(1000 * tick / self.rate)) & 0xFFFFFFFF
        for k, chunk in enumerate(chunks):
            payload = chunk.tobytes()
            counter_byte = k | (0x80 if k == len(chunks) - 1 else 0)
            header = struct.pack(_HEADER, b"MXTP02", counter, counter_byte, len(chunk), time_code, actor, 23,
                                 self.props, self.fingers, 0, len(payload))
            out.append(header + payload)
        return out

    def meta(self, actor):
        text = f"name:{self.names[actor]}\nxmid:{1000 + actor}\ncolor:FF8800\n".encode()
        return struct.pack(_HEADER, b"MXTP12", self.counters[actor], 0x80, 0, 0, actor, 23, self.props,
                           self.fingers, 0, len(text)) + text

    # -- faults ---------------------------------------------------------------------------
    def fault(self, kind, n=1):
        """One-shot faults on the next datagrams: 'drop', 'duplicate', 'reorder' (the next two
        swapped), 'garbage' (a stray datagram), 'other' (a type 21 datagram), 'restart' (the
        sample counters start again from 0)."""
        with self._lock:
            self._faults.extend([kind] * n)

    def _send(self, data):
        fault = self._faults.pop(0) if self._faults else None
        if fault == "restart":
            self.counters = {a: 0 for a in self.actors}
            fault = None
        if fault == "garbage":
            self.sock.sendto(bytes(np.random.default_rng(self.datagrams).integers(0, 256, 97, dtype=np.uint8)),
                             self.address)
        elif fault == "other":
            self.sock.sendto(struct.pack(_HEADER, b"MXTP21", 0, 0x80, 1, 0, 0, 23, 0, 0, 0, 40) + bytes(40),
                             self.address)
        if fault == "drop":
            return
        if fault == "reorder":
            self._held = data
            return
        self.sock.sendto(data, self.address)
        self.datagrams += 1
        if fault == "duplicate":
            self.sock.sendto(data, self.address)
        if self._held is not None:
            held, self._held = self._held, None
            self.sock.sendto(held, self.address)

    def tick(self):
        with self._lock:
            for actor in self.actors:
                counter = self.counters[actor]
                if self.meta_every and counter % self.meta_every == 0:
                    self._send(self.meta(actor))
                datagrams = self.datagrams_of(actor, self.tick_count, counter)
                now = time.perf_counter()  # when the sample leaves (a real streamer has it ready)
                for dg in datagrams:
                    self._send(dg)
                self.sent[(actor, counter)] = (self.tick_count, now)
                self.counters[actor] = (counter + 1) & 0xFFFFFFFF
            self.tick_count += 1

    # -- the loop -------------------------------------------------------------------------
    def start(self):
        self._running = True
        self._thread = threading.Thread(target=self._loop, name="humananim-mvn-sender", daemon=True)
        self._thread.start()
        return self

    def _loop(self):
        period = 1.0 / (self.rate * self.speed)
        next_t = time.perf_counter()
        while self._running:
            now = time.perf_counter()
            if now < next_t:
                time.sleep(min(next_t - now, 0.005))
                continue
            if not self.paused:
                self.tick()
            next_t += period
            if next_t < now - 0.5:
                next_t = now

    def stop(self):
        self._running = False
        if self._thread is not None:
            self._thread.join(2.0)
        self.sock.close()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()
