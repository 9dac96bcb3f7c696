"""``micros-rt run --hints``: the same protocols, names and order as TransportHints in code."""

from __future__ import annotations

import pytest

from micros_rt import TransportHints
from micros_rt.cli import CommandError
from micros_rt.cli.run import _parser, parse_hints


def test_the_default_is_the_librarys_default_shared_memory_first() -> None:
    assert parse_hints(_parser().parse_args([]).hints) == TransportHints()
    assert parse_hints("shm,dds,tcp").protocols == ("SHM", "DDS", "TCPROS")


def test_orders_and_refusals() -> None:
    assert parse_hints("dds,tcpros").protocols == ("DDS", "TCPROS")  # never shared memory
    assert parse_hints("TCP").protocols == ("TCPROS",)
    with pytest.raises(CommandError, match="unknown protocol 'udp'.*shm, dds, tcp"):
        parse_hints("udp")
    with pytest.raises(CommandError, match="give shm, dds, tcp"):
        parse_hints(" , ")
