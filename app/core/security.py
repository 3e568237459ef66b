"""Passwords (argon2), API keys (sha256 of a random token) and webhook signatures."""

from __future__ import annotations

import hashlib
import hmac
import os
import secrets
import time
from pathlib import Path

from argon2 import PasswordHasher
from argon2.exceptions import InvalidHashError, VerificationError

_hasher = PasswordHasher()

API_KEY_PREFIX = "mc_"
#: Characters of a key shown in lists ("mc_" + 8 random characters).
SHOWN_PREFIX_LEN = 11


def hash_password(password: str) -> str:
    return _hasher.hash(password)


def verify_password(password: str, password_hash: str | None) -> bool:
    if not password_hash:
        return False
    try:
        return _hasher.verify(password_hash, password)
    except (VerificationError, InvalidHashError):
        return False


def new_api_key() -> tuple[str, str, str]:
    """A fresh key: ``(key, shown prefix, sha256 hex)``; only the last two are stored."""
    key = API_KEY_PREFIX + secrets.token_urlsafe(32)
    return key, key[:SHOWN_PREFIX_LEN], hash_api_key(key)


def hash_api_key(key: str) -> str:
    return hashlib.sha256(key.encode()).hexdigest()


def new_webhook_secret() -> str:
    return "whsec_" + secrets.token_urlsafe(32)


#: How far a webhook's ``X-Coach-Timestamp`` may be from the receiver's clock, in seconds.
WEBHOOK_TOLERANCE_S = 300.0


def sign_webhook(body: bytes, secret: str, timestamp: int) -> str:
    """The ``X-Coach-Signature`` header value of a delivery sent at ``timestamp``.

    ``sha256=<hex HMAC-SHA256 with the secret of "<timestamp>.<body>">``; ``timestamp`` is
    the ``X-Coach-Timestamp`` header (unix seconds). Signing the time with the body lets a
    receiver refuse a captured delivery replayed later.
    """
    signed = str(int(timestamp)).encode() + b"." + body
    return "sha256=" + hmac.new(secret.encode(), signed, hashlib.sha256).hexdigest()


def verify_webhook(
    body: bytes,
    secret: str,
    signature: str,
    timestamp: str | int,
    *,
    tolerance_s: float = WEBHOOK_TOLERANCE_S,
    now: float | None = None,
) -> bool:
    """What a receiver does: refuse a timestamp more than ``tolerance_s`` seconds from its
    clock (``now``, default the current time) either way, then recompute the signature and
    compare in constant time. The body's ``delivery_id`` (also ``X-Coach-Delivery``) is the
    same for every retry of one event: keep the ids seen within the tolerance to drop
    repeats."""
    try:
        sent = int(str(timestamp).strip())
    except ValueError:
        return False
    if abs((time.time() if now is None else now) - sent) > tolerance_s:
        return False
    return hmac.compare_digest(sign_webhook(body, secret, sent), signature)


#: File in the data directory holding the generated session secret.
SECRET_FILE = "secret_key"


def stored_secret(data_dir: Path) -> str:
    """The data directory's session secret, generated on first use (mode 0600).

    ``O_EXCL`` makes the first of several starting processes the only writer; the others
    read what it wrote, so every API process behind one data volume signs alike.
    """
    path = data_dir / SECRET_FILE
    data_dir.mkdir(parents=True, exist_ok=True)
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        for _ in range(50):  # another process may be between its create and its write
            secret = path.read_text().strip()
            if secret:
                return secret
            time.sleep(0.02)
        raise RuntimeError(f"{path} is empty; delete it to have a new secret generated") from None
    secret = secrets.token_urlsafe(48)
    with os.fdopen(fd, "w") as f:
        f.write(secret)
    return secret


def new_session_token() -> tuple[str, str]:
    """A browser session: ``(token for the cookie, sha256 hex stored server-side)``."""
    token = secrets.token_urlsafe(32)
    return token, hash_api_key(token)


#: A hash verified when no account matches, so a wrong email costs what a wrong password does.
_DUMMY_HASH = _hasher.hash(secrets.token_urlsafe(16))


def verify_nothing(password: str) -> None:
    """Spend one password verification's time (constant-time sign-in for unknown emails)."""
    verify_password(password, _DUMMY_HASH)
