"""Shared memory's negotiation (pure): the offer and answer on the wire, and the publisher's verdict."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

from micros_rt import AdvertiseQoSOptions, SubscribeQoSOptions
from micros_rt.negotiation import SHM, MalformedNegotiationError, PublicationFacts, TransportHints, choose_protocol
from micros_rt.transports.shm.offer import ShmAnswer, ShmOffer, decide_shm
from micros_rt.negotiation.choose import OfferJudge
from micros_rt.transports.shm import host_identity

HOST = "0b1d/4026531840/4026531841/1000"
FACTS = PublicationFacts("/chatter", "", None, "std_msgs/String", "992ce8a1687cec8c8bd883ec73ca41d1",
                         AdvertiseQoSOptions(), latch=False)


def offer(**kw: object) -> ShmOffer:
    base = dict(host=HOST, md5=FACTS.md5, type_name="std_msgs/String", qos=SubscribeQoSOptions())
    base.update(kw)
    return ShmOffer(**base)  # type: ignore[arg-type]


def test_offer_and_answer_round_trip() -> None:
    o = offer(transient_local=True, pid=77)
    entry = o.to_xmlrpc()
    assert entry[0] == SHM and ShmOffer.from_xmlrpc(entry[1]) == o
    a = ShmAnswer(channel="micros_rt/0000abcd00000001deadbeef", latch=True,
                  qos=AdvertiseQoSOptions(msg_valid_period=2.0), node="/talker", pid=4242)
    assert ShmAnswer.from_xmlrpc(a.to_xmlrpc()[1]) == a
    # a subscriber asking again names the channel it reads; an older subscriber's offer has no such key
    held = offer(pid=77, held="micros_rt/0000abcd00000001deadbeef")
    assert ShmOffer.from_xmlrpc(held.to_xmlrpc()[1]) == held
    assert "held" not in o.to_xmlrpc()[1] and ShmOffer.from_xmlrpc(o.to_xmlrpc()[1]).held == ""


@pytest.mark.parametrize("params,field", [
    ({"channel": "/dev/shm/../../etc/passwd", "latch": False, "qos": {}}, "channel"),
    ({"channel": "micros_rt/00", "latch": False, "qos": {}}, "channel"),
    ({"channel": "micros_rt/0000abcd00000001", "latch": "yes", "qos": {}}, "latch"),
    ({"channel": "micros_rt/0000abcd00000001", "latch": False, "qos": {"deadline": "soon"}}, "qos"),
    ([], "SHM answer"),
    ({"channel": "micros_rt/0000abcd00000001", "latch": False, "qos": {}, "pid": -4}, "pid"),
    ({"channel": "micros_rt/0000abcd00000001", "latch": False, "qos": {}, "pid": "1234"}, "pid"),
])
def test_malformed_answers_are_refused_naming_the_field(params: object, field: str) -> None:
    with pytest.raises(MalformedNegotiationError) as err:
        ShmAnswer.from_xmlrpc(params)
    assert err.value.field == field


def test_malformed_offer_is_refused() -> None:
    with pytest.raises(MalformedNegotiationError) as err:
        ShmOffer.from_xmlrpc({"host": 5, "md5": "*", "type": "std_msgs/String"})
    assert err.value.field == "host"


def test_same_host_and_user_is_accepted() -> None:
    verdict = decide_shm(offer(), FACTS, host=HOST, unavailable=None, subscriber="/listener")
    assert verdict.accepted and verdict.kind == "accepted"


def test_another_host_is_declined_quietly() -> None:
    verdict = decide_shm(offer(host="ffff/1/2/1000"), FACTS, host=HOST, unavailable=None, subscriber="/l")
    assert not verdict.accepted and verdict.quiet and "another host" in verdict.reason


def test_another_network_namespace_is_another_host() -> None:
    # the suite's and the benchmarks' "hosts" are network namespaces of one machine: they must use the network
    verdict = decide_shm(offer(host="0b1d/99/4026531841/1000"), FACTS, host=HOST, unavailable=None, subscriber="/l")
    assert not verdict.accepted and verdict.quiet


def test_another_user_is_declined_in_words() -> None:
    verdict = decide_shm(offer(host="0b1d/4026531840/4026531841/1001"), FACTS, host=HOST, unavailable=None,
                         subscriber="/l")
    assert not verdict.accepted and not verdict.quiet and "another Unix user" in verdict.reason


def test_unavailable_type_and_qos_mismatches_say_why() -> None:
    v = decide_shm(offer(), FACTS, host=HOST, unavailable="/dev/shm has 3 MiB free", subscriber="/l")
    assert not v.accepted and "/dev/shm has 3 MiB free" in v.reason
    v = decide_shm(offer(md5="0" * 32), FACTS, host=HOST, unavailable=None, subscriber="/l")
    assert not v.accepted and v.kind == "md5"
    best_effort = PublicationFacts(FACTS.topic, "", None, FACTS.type_name, FACTS.md5,
                                   AdvertiseQoSOptions(using_best_effort_protocol=True), latch=False)
    v = decide_shm(offer(), best_effort, host=HOST, unavailable=None, subscriber="/l")
    assert not v.accepted and v.kind == "qos:using_best_effort_protocol"


def test_a_stock_publisher_skips_the_shm_entry_silently() -> None:
    choice = choose_protocol([offer().to_xmlrpc(), ["TCPROS"]], negotiated={}, supports=lambda n: n == "TCPROS",
                             subscriber="/l", topic="/chatter")
    assert choice.entry == ["TCPROS"] and not choice.declined


def test_a_declined_shm_offer_falls_to_the_next_protocol() -> None:
    def judge(o: ShmOffer) -> tuple:  # type: ignore[type-arg]
        return decide_shm(o, FACTS, host="ffff/1/2/3", unavailable=None, subscriber="/l"), None

    transport = OfferJudge(parse=lambda p, s: ShmOffer.from_xmlrpc(p, source=s), judge=judge)
    choice = choose_protocol([offer().to_xmlrpc(), ["TCPROS"]], negotiated={SHM: transport},
                             supports=lambda n: n == "TCPROS", subscriber="/l", topic="/chatter")
    assert choice.entry == ["TCPROS"] and [v.kind for v in choice.declined] == ["shm-host"]


def test_default_hints_offer_shm_first() -> None:
    assert TransportHints().protocols[0] == SHM
    assert TransportHints().tcp().protocols == ("TCPROS",)


def test_host_identity_tells_users_and_namespaces_apart() -> None:
    ident = host_identity()
    boot, net, mnt, uid, scheme = ident.split("/")
    assert uid == str(os.getuid()) and net.isdigit() and mnt.isdigit() and boot != "?" and scheme == "u"
    # another network namespace (as the suite's netns hosts) gives another identity
    if os.geteuid() == 0 and os.path.exists("/usr/bin/unshare"):
        out = subprocess.run(["unshare", "--net", sys.executable, "-c",
                              "from micros_rt.transports.shm import host_identity; print(host_identity())"],
                             capture_output=True, text=True, timeout=60)
        assert out.returncode == 0, out.stderr
        other = out.stdout.strip().split("/")
        assert other[0] == boot and other[1] != net and other[3] == uid


def test_unavailable_reason_in_words_when_turned_off() -> None:
    out = subprocess.run([sys.executable, "-c", "from micros_rt.transports.shm import unavailable_reason as u; "
                          "print(u())"], capture_output=True, text=True, timeout=60,
                         env={**os.environ, "MICROS_RT_DISABLE_SHM": "1"})
    assert "MICROS_RT_DISABLE_SHM" in out.stdout
    out = subprocess.run([sys.executable, "-c", "from micros_rt.transports.shm import unavailable_reason as u; "
                          "print(u())"], capture_output=True, text=True, timeout=60,
                         env={**os.environ, "MICROS_RT_DISABLE_SHM": "0"})
    assert out.stdout.strip() == "None", out.stdout + out.stderr


def test_a_dead_or_unreaped_peer_process_is_dead() -> None:
    from micros_rt.transports.shm.host import process_alive

    assert process_alive(os.getpid()) and process_alive(0)
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    deadline = time.monotonic() + 30
    while process_alive(child.pid):  # a zombie until reaped: dead for the channel's peer check
        assert time.monotonic() < deadline, "an exited, unreaped child still reads as alive"
        time.sleep(0.01)
    child.wait()
    assert not process_alive(child.pid)
