"""The transport contract (:mod:`contract.checks`) against every transport that runs in this process: the fake
in-memory transport, DDS (loopback, this run's domain), the microcontroller UDP link (loopback) and MQTT through
a real mosquitto, shared memory (iceoryx2, in this process). TCPROS needs a master and a node: ``test_contract_tcpros.py`` runs the same checks there."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Dict, Iterator

import pytest

from contract.checks import CHECKS, Pair
from contract.pairs import dds_pair, fake_pair, mcu_pair, mqtt_pair, shm_pair


@pytest.fixture(scope="module")
def mosquitto(tmp_path_factory: pytest.TempPathFactory) -> Iterator[int]:
    from mqtt_broker import MosquittoBroker

    broker = MosquittoBroker(Path(tmp_path_factory.mktemp("contract_mqtt"))).start()
    try:
        yield broker.port
    finally:
        broker.stop()


MAKERS: Dict[str, Callable[[Any], Pair]] = {
    "fake": lambda _request: fake_pair(),
    "dds": lambda _request: dds_pair(),
    "mcu": lambda _request: mcu_pair(),
    "mqtt": lambda request: mqtt_pair(request.getfixturevalue("mosquitto")),
    "shm": lambda _request: shm_pair(),
}


@pytest.fixture(params=sorted(MAKERS))
def pair(request: Any) -> Iterator[Pair]:
    made = MAKERS[request.param](request)
    try:
        yield made
    finally:
        made.writer.close()
        made.reader.close()
        made.cleanup()


@pytest.mark.parametrize("check", CHECKS, ids=[c.__name__.removeprefix("check_") for c in CHECKS])
def test_transport_contract(pair: Pair, check: Callable[[Pair], None]) -> None:
    check(pair)
