"""Per-key token buckets and the sign-in throttle.

In memory for one API process (``coach serve``). With several API processes, the Redis
variants keep the same counts in Redis, so N processes do not give an attacker N times the
attempts (issue 26). They read Redis' clock, not the processes' own, and fall back to the
in-memory counts while Redis cannot be reached: limits then hold per process, as before,
rather than locking everybody out or letting everybody in.
"""

from __future__ import annotations

import hashlib
import logging
import math
import threading
import time
from typing import Any

log = logging.getLogger("app.ratelimit")


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


# ---- shared in Redis
# Lua: each call is atomic in Redis, and TIME is Redis' clock (the same for every API process).
_NOW = """
if redis.replicate_commands then redis.replicate_commands() end
local t = redis.call('TIME')
local now = tonumber(t[1]) + tonumber(t[2]) / 1e6
"""
_TAKE = _NOW + """
local rate, burst = tonumber(ARGV[1]), tonumber(ARGV[2])
local b = redis.call('HMGET', KEYS[1], 'tokens', 'last')
local tokens, last = tonumber(b[1]) or burst, tonumber(b[2]) or now
tokens = math.min(burst, tokens + math.max(0, now - last) * rate)
local wait = 0
if tokens >= 1 then tokens = tokens - 1 else wait = (1 - tokens) / rate end
redis.call('HSET', KEYS[1], 'tokens', tostring(tokens), 'last', tostring(now))
redis.call('EXPIRE', KEYS[1], math.ceil(burst / rate) + 1)
return tostring(wait)
"""
_WAIT = _NOW + """
local wait = 0
for i, key in ipairs(KEYS) do
  local untl = tonumber(redis.call('HGET', key, 'until')) or 0
  wait = math.max(wait, untl - now)
end
return tostring(wait)
"""
# ARGV: backoff_s, max_lock_s, then the free failures of each key.
_FAILED = _NOW + """
local backoff, max_lock = tonumber(ARGV[1]), tonumber(ARGV[2])
for i, key in ipairs(KEYS) do
  local n = redis.call('HINCRBY', key, 'n', 1)
  local over = n - tonumber(ARGV[2 + i])
  local lock = 0
  if over >= 0 then
    lock = math.min(max_lock, backoff * 2 ^ over)
    redis.call('HSET', key, 'until', tostring(now + lock))
  end
  -- forgotten max_lock_s after its last failure, once any lock is over
  redis.call('EXPIRE', key, math.ceil(lock + max_lock))
end
return 0
"""


def _redis_client(url: str) -> tuple[Any, type[Exception]]:
    """A client of ``url`` and the exception its failures raise (redis is the worker's
    dependency: imported only when the limits are shared)."""
    import redis

    # Short timeouts: a sign-in must not hang on a slow Redis; the fallback answers then.
    client = redis.Redis.from_url(url, socket_timeout=0.5, socket_connect_timeout=0.5)
    return client, redis.RedisError


class _Fallback:
    """Logs Redis failures at most once a minute; the caller then uses its in-memory counts."""

    def __init__(self) -> None:
        self._last_warning = -math.inf

    def warn(self, exc: Exception) -> None:
        now = time.monotonic()
        if now - self._last_warning > 60:
            self._last_warning = now
            log.warning("limits kept per process while Redis is unreachable: %s", exc)


class RedisRateLimiter(RateLimiter):
    """:class:`RateLimiter` whose buckets live in Redis, shared by every API process."""

    def __init__(self, url: str, rate_per_s: float, burst: int, prefix: str = "coach:rl:") -> None:
        super().__init__(rate_per_s, burst)
        self.prefix, self._fallback = prefix, _Fallback()
        self._redis, self._errors = _redis_client(url)
        self._take = self._redis.register_script(_TAKE)

    def take(self, key: object) -> float:
        try:
            return float(self._take(keys=[f"{self.prefix}{key}"], args=[self.rate, self.burst]))
        except self._errors as exc:
            self._fallback.warn(exc)
            return super().take(key)


class RedisSignInThrottle(SignInThrottle):
    """:class:`SignInThrottle` whose counts live in Redis, shared by every API process.

    Keys are hashed, so Redis holds no email address; each expires ``max_lock_s`` after its
    last failure once its lock is over, which bounds what random emails can fill.
    """

    def __init__(self, url: str, *, prefix: str = "coach:signin:", **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.prefix, self._fallback = prefix, _Fallback()
        self._redis, self._errors = _redis_client(url)
        self._wait = self._redis.register_script(_WAIT)
        self._failed = self._redis.register_script(_FAILED)

    def _name(self, key: tuple[str, str]) -> str:
        return self.prefix + hashlib.sha256("\0".join(key).encode()).hexdigest()[:32]

    def wait(self, keys: list[tuple[str, str]]) -> float:
        try:
            return float(self._wait(keys=[self._name(k) for k in keys]))
        except self._errors as exc:
            self._fallback.warn(exc)
            return super().wait(keys)

    def failed(self, keys: list[tuple[str, str]]) -> None:
        args = [self.backoff_s, self.max_lock_s, *(self.free[k[0]] for k in keys)]
        try:
            self._failed(keys=[self._name(k) for k in keys], args=args)
        except self._errors as exc:
            self._fallback.warn(exc)
            super().failed(keys)

    def succeeded(self, email: str) -> None:
        try:
            self._redis.delete(self._name(self.keys(email, "")[0]))
        except self._errors as exc:
            self._fallback.warn(exc)
        super().succeeded(email)


def limits_for(settings: Any) -> tuple[RateLimiter, SignInThrottle]:
    """The API key buckets and the sign-in throttle for ``settings`` (app.core.config):
    shared in Redis when ``settings.shared_limits_url`` names one, else in memory."""
    throttle = {
        "free_per_account": settings.signin_free_per_account,
        "free_per_ip": settings.signin_free_per_ip,
        "backoff_s": settings.signin_backoff_s,
        "max_lock_s": settings.signin_max_lock_s,
    }
    url = settings.shared_limits_url
    if url is None:
        return (
            RateLimiter(settings.rate_limit_per_s, settings.rate_limit_burst),
            SignInThrottle(**throttle),
        )
    return (
        RedisRateLimiter(url, settings.rate_limit_per_s, settings.rate_limit_burst),
        RedisSignInThrottle(url, **throttle),
    )
