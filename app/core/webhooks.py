"""Where completion webhooks may go: public http(s) addresses only.

A club chooses its webhook URL, so without a check the service would POST wherever a club
says: to services listening on its own loopback, a cloud metadata endpoint
(169.254.169.254) or the private network it runs in (server-side request forgery). The host
is resolved (``socket.getaddrinfo``, which also reads every other spelling of an address:
``2130706433``, ``0x7f.1``, ``0177.0.0.1``) and each address it resolves to must be public:
global in :mod:`ipaddress` terms and not private, loopback, link-local, multicast, reserved or
unspecified, nor an IPv4 address of that kind inside an IPv4-mapped, 6to4 or Teredo IPv6
address.

The check runs when a club sets the URL and again before every delivery, and a delivery
connects to the very address that was checked (the name still goes in ``Host`` and, for
https, in the TLS server name), so a name that resolves elsewhere the second time (DNS
rebinding) cannot slip through. Redirects are not followed. Deliveries ignore the proxy
environment variables: the address checked must be the address connected to.
"""

from __future__ import annotations

import ipaddress
import socket
from dataclasses import dataclass

import httpx

SCHEMES = ("http", "https")
DEFAULT_PORTS = {"http": 80, "https": 443}

IPAddress = ipaddress.IPv4Address | ipaddress.IPv6Address

#: ``ipaddress`` properties that make an address internal, and what to call it.
_INTERNAL = (
    ("is_unspecified", "unspecified"),
    ("is_loopback", "loopback"),
    ("is_link_local", "link-local"),
    ("is_multicast", "multicast"),
    ("is_private", "private"),
    ("is_reserved", "reserved"),
    ("is_site_local", "site-local"),
)


class WebhookUrlError(ValueError):
    """The URL cannot receive webhooks now; the message says why in words a club reads."""


class UnsafeWebhookUrl(WebhookUrlError):
    """The URL may never receive webhooks: not http(s), or an internal address."""


class UnresolvedHost(WebhookUrlError):
    """The host does not resolve (may be transient: a delivery retries it)."""


@dataclass(frozen=True)
class Destination:
    """A checked webhook URL, pinned to the address that was checked."""

    #: The URL with its host replaced by :attr:`address`.
    url: str
    #: The ``Host`` header: the URL's own host and port.
    host_header: str
    #: The name TLS verifies the certificate against (https to a name), else None.
    sni_hostname: str | None
    address: str


def internal_kind(ip: IPAddress) -> str | None:
    """What makes ``ip`` internal ("loopback", "private", ...), or None for a public one."""
    candidates: list[IPAddress] = []
    if isinstance(ip, ipaddress.IPv6Address):  # the IPv4 address inside names it best
        embedded = [ip.ipv4_mapped, ip.sixtofour, *(ip.teredo or ())]
        candidates += [a for a in embedded if a is not None]
    candidates.append(ip)
    for a in candidates:
        for prop, kind in _INTERNAL:
            if getattr(a, prop, False):
                return kind
        if not a.is_global:
            return "non-public"
    return None


def destination(url: str, *, allow_private: bool = False) -> Destination:
    """Resolve ``url``'s host and check every address it has.

    Parameters
    ----------
    url : str
        An absolute http or https URL.
    allow_private : bool, keyword-only
        Skip the address check (``COACH_WEBHOOK_ALLOW_PRIVATE``: tests, a receiver on the
        same host). The scheme is checked regardless.

    Returns
    -------
    Destination
        The URL pinned to the first address the host resolves to.

    Raises
    ------
    UnsafeWebhookUrl
        Not an http(s) URL with a host, or the host resolves to an internal address.
    UnresolvedHost
        The host does not resolve.
    """
    try:
        u = httpx.URL(url)
    except (httpx.InvalidURL, TypeError, ValueError):
        raise UnsafeWebhookUrl("it is not a valid URL") from None
    if u.scheme not in SCHEMES:
        raise UnsafeWebhookUrl("only http and https URLs can receive webhooks")
    host = u.raw_host.decode("ascii")
    if not host:
        raise UnsafeWebhookUrl("the URL has no host")
    port = u.port or DEFAULT_PORTS[u.scheme]
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except (OSError, UnicodeError):
        raise UnresolvedHost(f"the host {host} cannot be resolved") from None
    # A scoped IPv6 address ("fe80::1%eth0") is link-local whatever its scope.
    addresses = list(dict.fromkeys(ipaddress.ip_address(i[4][0].split("%")[0]) for i in infos))
    if not addresses:
        raise UnresolvedHost(f"the host {host} cannot be resolved")
    if not allow_private:
        for ip in addresses:
            if kind := internal_kind(ip):
                what = host if _ip(host) == ip else f"{host} resolves to {ip}, which"
                article = "an" if kind[0] in "aeiou" else "a"
                raise UnsafeWebhookUrl(
                    f"{what} is {article} {kind} address; webhooks go only to public addresses"
                )
    address = str(addresses[0])
    return Destination(
        url=str(u.copy_with(host=address)),
        host_header=u.netloc.decode("ascii"),
        sni_hostname=host if u.scheme == "https" and _ip(host) is None else None,
        address=address,
    )


def _ip(host: str) -> IPAddress | None:
    """The address a host written as an IP literal is (None for a name)."""
    try:
        return ipaddress.ip_address(host.strip("[]"))
    except ValueError:
        return None


def post(
    dest: Destination, body: bytes, headers: dict[str, str], *, timeout_s: float
) -> httpx.Response:
    """POST ``body`` to the pinned address; a redirect comes back as it is, not followed.

    Raises ``httpx.HTTPError`` for connection and timeout failures.
    """
    extensions = {"sni_hostname": dest.sni_hostname} if dest.sni_hostname else {}
    with httpx.Client(timeout=timeout_s, follow_redirects=False, trust_env=False) as client:
        return client.post(
            dest.url,
            content=body,
            headers={**headers, "Host": dest.host_header},
            extensions=extensions,
        )
