"""Room tokens: who may publish into or watch a room, until when.

A token is ``base64url(claims JSON) "." base64url(HMAC-SHA256(secret, claims))`` with claims
``{"room", "role" (publish, subscribe or both), "exp" (Unix seconds)}``. The relay checks the
signature in constant time, the expiry, the room and the role; ``mocodec token`` issues one.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import json
import time

from mocodec.errors import MocodecError

ROLES = ("publish", "subscribe", "both")


class TokenError(MocodecError):
    """A token is malformed, forged, expired, or not for this room or role."""


def _b64(data: bytes) -> str:
    return base64.urlsafe_b64encode(data).rstrip(b"=").decode()


def _unb64(text: str) -> bytes:
    return base64.urlsafe_b64decode(text + "=" * (-len(text) % 4))


def _sign(secret: str, claims: bytes) -> bytes:
    return hmac.new(secret.encode(), claims, hashlib.sha256).digest()


def issue(secret: str, room: str, role: str = "both", ttl_s: float = 3600.0, now: float | None = None) -> str:
    if not secret:
        raise TokenError("the server secret is empty")
    if role not in ROLES:
        raise TokenError(f"role must be one of {', '.join(ROLES)}, got {role!r}")
    if not room:
        raise TokenError("the room name is empty")
    if not ttl_s > 0:
        raise TokenError(f"the token lifetime must be positive, got {ttl_s}")
    exp = int((time.time() if now is None else now) + ttl_s)
    claims = json.dumps({"room": room, "role": role, "exp": exp}, sort_keys=True, separators=(",", ":")).encode()
    return f"{_b64(claims)}.{_b64(_sign(secret, claims))}"


def verify(secret: str, token: str, room: str, role: str, now: float | None = None) -> dict:
    """The token's claims; TokenError saying why it is refused."""
    try:
        head, sig = token.split(".")
        claims_raw, given = _unb64(head), _unb64(sig)
    except (ValueError, TypeError):
        raise TokenError("malformed token (expected two base64 parts joined by '.')") from None
    if not hmac.compare_digest(given, _sign(secret, claims_raw)):
        raise TokenError("bad token signature (wrong secret, or the token was altered)")
    claims = json.loads(claims_raw)
    if claims.get("exp", 0) < (time.time() if now is None else now):
        raise TokenError("token expired")
    if claims.get("room") != room:
        raise TokenError(f"token is for room {claims.get('room')!r}, not {room!r}")
    if claims.get("role") not in (role, "both"):
        raise TokenError(f"token allows {claims.get('role')}, not {role}")
    return claims
