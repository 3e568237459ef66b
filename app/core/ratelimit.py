"""Per-key token buckets.

In memory, per API process: with several API processes each allows the full rate, which is
acceptable for abuse protection; a shared limit would need Redis.
"""

from __future__ import annotations

import threading
import time


class RateLimiter:
    def __init__(self, rate_per_s: float, burst: int) -> None:
        self.rate = float(rate_per_s)
        self.burst = float(burst)
        self._buckets: dict[object, tuple[float, float]] = {}  # key -> (tokens, last time)
        self._lock = threading.Lock()

    def take(self, key: object) -> float:
        """Take one token; returns 0 when allowed, else the seconds until one is available."""
        now = time.monotonic()
        with self._lock:
            tokens, last = self._buckets.get(key, (self.burst, now))
            tokens = min(self.burst, tokens + (now - last) * self.rate)
            if tokens >= 1.0:
                self._buckets[key] = (tokens - 1.0, now)
                return 0.0
            self._buckets[key] = (tokens, now)
            return (1.0 - tokens) / self.rate


class SignInThrottle:
    """Failed sign-ins per account and per client address, with an exponential lock-out.

    Each key (``("email", ...)``, ``("ip", ...)``) gets ``free`` failures; every further one
    doubles its lock (``backoff_s``, ``2 * backoff_s``, ... up to ``max_lock_s``). A key with
    no failure for ``max_lock_s`` is forgotten, and at most ``max_keys`` are kept, so random
    emails cannot grow the table without bound. In memory per API process, like the buckets.
    """

    def __init__(
        self, *, free_per_account: int, free_per_ip: int, backoff_s: float, max_lock_s: float,
        max_keys: int = 100_000,
    ) -> None:  # fmt: skip
        self.free = {"email": free_per_account, "ip": free_per_ip}
        self.backoff_s, self.max_lock_s, self.max_keys = backoff_s, max_lock_s, max_keys
        self._entries: dict[tuple[str, str], tuple[int, float, float]] = {}  # failures, last, until
        self._lock = threading.Lock()

    @staticmethod
    def keys(email: str, ip: str) -> list[tuple[str, str]]:
        return [("email", email.strip().lower()), ("ip", ip)]

    def wait(self, keys: list[tuple[str, str]]) -> float:
        """Seconds until these keys may try again (0: now)."""
        now = time.monotonic()
        with self._lock:
            return max((self._entries.get(k, (0, 0.0, 0.0))[2] - now for k in keys), default=0.0)

    def failed(self, keys: list[tuple[str, str]]) -> None:
        now = time.monotonic()
        with self._lock:
            self._forget_stale(now)
            for key in keys:
                n, _, until = self._entries.get(key, (0, now, 0.0))
                n += 1
                over = n - self.free[key[0]]
                if over >= 0:
                    until = now + min(self.max_lock_s, self.backoff_s * 2.0**over)
                self._entries[key] = (n, now, until)

    def succeeded(self, email: str) -> None:
        """A right password clears the account's count (not the address's)."""
        with self._lock:
            self._entries.pop(("email", email.strip().lower()), None)

    def _forget_stale(self, now: float) -> None:
        if len(self._entries) < self.max_keys:
            return
        stale = [k for k, (_, last, until) in self._entries.items()
                 if now - last > self.max_lock_s and until <= now]  # fmt: skip
        for k in stale:
            del self._entries[k]
        if len(self._entries) >= self.max_keys:  # all fresh: drop the oldest half
            by_age = sorted(self._entries, key=lambda k: self._entries[k][1])
            for k in by_age[: len(by_age) // 2]:
                del self._entries[k]
