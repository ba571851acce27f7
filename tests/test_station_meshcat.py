"""Meshcat must listen on the loopback interface only (Drake's default listens on all)."""

from __future__ import annotations

import ipaddress
from pathlib import Path

from sustain_drake.station.meshcat import make_local_meshcat

LISTEN = "0A"  # TCP state LISTEN in /proc/net/tcp*


def _address(hex_address: str, v6: bool) -> ipaddress._BaseAddress:
    raw = bytes.fromhex(hex_address)
    # /proc/net/tcp* prints the address as 32-bit words in host (little-endian) byte order.
    words = [raw[i:i + 4][::-1] for i in range(0, len(raw), 4)]
    packed = b"".join(words)
    return ipaddress.IPv6Address(packed) if v6 else ipaddress.IPv4Address(packed)


def listening_addresses(port: int) -> list[ipaddress._BaseAddress]:
    """The local addresses of sockets listening on ``port`` (read from /proc/net/tcp{,6})."""
    found = []
    for name, v6 in (("tcp", False), ("tcp6", True)):
        table = Path("/proc/net") / name
        if not table.exists():
            continue
        for line in table.read_text().splitlines()[1:]:
            fields = line.split()
            local, state = fields[1], fields[3]
            hex_address, hex_port = local.split(":")
            if state == LISTEN and int(hex_port, 16) == port:
                found.append(_address(hex_address, v6))
    return found


def test_parser_reads_known_addresses():
    assert _address("0100007F", v6=False) == ipaddress.IPv4Address("127.0.0.1")
    assert _address("00000000", v6=False) == ipaddress.IPv4Address("0.0.0.0")
    assert _address("00000000000000000000000001000000", v6=True) == ipaddress.IPv6Address("::1")


def test_meshcat_listens_on_loopback_only():
    meshcat = make_local_meshcat()
    addresses = listening_addresses(meshcat.port())
    assert addresses, f"no listening socket found for port {meshcat.port()}"
    for address in addresses:
        # 0.0.0.0 / :: (all interfaces) or a real interface address would fail here.
        assert address.is_loopback, f"Meshcat listens on {address}"
    assert "localhost" in meshcat.web_url() or "127.0.0.1" in meshcat.web_url()
