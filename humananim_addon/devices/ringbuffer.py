"""A bounded, lock-protected ring buffer: the reader thread pushes, never blocks, and when
the consumer falls behind the oldest samples are overwritten and counted as dropped."""

import threading


class RingBuffer:
    def __init__(self, capacity=4096):
        if capacity < 1:
            raise ValueError("capacity must be at least 1")
        self.capacity = int(capacity)
        self._items = [None] * self.capacity
        self._head = 0  # next write position
        self._count = 0
        self._lock = threading.Lock()
        self.pushed = 0
        self.dropped = 0
        self._newest = None

    def push(self, item):
        self.push_many((item,))

    def push_many(self, items):
        """Push items as one: a consumer draining meanwhile sees all of them or none (the birds of
        one group-mode record must not be split between 'before recording' and the take)."""
        with self._lock:
            for item in items:
                self._items[self._head] = item
                self._head = (self._head + 1) % self.capacity
                if self._count == self.capacity:
                    self.dropped += 1  # overwrote the oldest unread sample
                else:
                    self._count += 1
                self.pushed += 1
                self._newest = item

    def drain(self):
        """Every unread sample, oldest first."""
        with self._lock:
            start = (self._head - self._count) % self.capacity
            if start + self._count <= self.capacity:
                out = self._items[start:start + self._count]
            else:
                out = self._items[start:] + self._items[:self._head]
            self._count = 0
            return out

    def newest(self):
        """The last sample pushed (read or not), without consuming anything."""
        return self._newest

    def __len__(self):
        return self._count
