"""The QoS catalogue (micros_rt.qos.options.OPTIONS) is the one place an option is described: the option
classes, their XML-RPC/YAML form, the DDS mapping, the enforcers and their counters, the CLI's words and the
bridges' key lists all follow it. A toy option added in the test shows what adding one costs."""

from __future__ import annotations

import dataclasses
from typing import Any

import pytest

from micros_rt.core.stats import SubscriberStatistics
from micros_rt.exceptions import QoSValueError
from micros_rt.qos import mapping, options
from micros_rt.qos.options import (OPTIONS, AdvertiseQoSOptions, QoSOption, SubscribeQoSOptions, describe,
                                   drop_counters, enforcers, options_of, wire_keys)
from micros_rt.bridges.mcu import config as mcu_config


@pytest.mark.parametrize("side,cls", [("advertise", AdvertiseQoSOptions), ("subscribe", SubscribeQoSOptions)])
def test_the_option_classes_are_the_catalogue(side: str, cls: Any) -> None:
    assert {f.name for f in dataclasses.fields(cls)} == {o.name for o in options_of(side)}
    assert set(cls().to_dict()) == set(wire_keys(side)) == set(cls._KEYS)
    assert cls.from_dict(cls().to_dict()) == cls()


def test_every_enforcer_counts_its_drops_and_every_dds_policy_has_a_builder() -> None:
    stats = {f.name for f in dataclasses.fields(SubscriberStatistics)}
    for option in OPTIONS:
        if option.enforcer is not None:
            assert option.counter in stats, option
    builders = mapping._policy_builders()
    assert {o.dds_policy for o in OPTIONS if o.dds_policy} <= set(builders)
    assert enforcers() == {"time_filter", "lifespan", "source_order", "deadline"}


def test_drop_counters_are_the_enforcers_counters() -> None:
    assert drop_counters() == ("dropped_expired", "deadline_missed", "dropped_filtered", "dropped_out_of_order")
    assert set(drop_counters()) == {o.counter for o in OPTIONS if o.enforcer is not None}
    assert drop_counters(side="subscribe", applies=options.MCU_FROM) == ("deadline_missed", "dropped_filtered")
    assert drop_counters(applies=options.MCU_TO) == ("dropped_expired", "dropped_filtered")
    assert drop_counters(side="advertise") == ("dropped_expired",)


def test_a_new_enforcer_s_counter_reaches_the_relay_and_the_graph_tool(monkeypatch: pytest.MonkeyPatch) -> None:
    # The relay's import counters and micros-rt graph's words for them take the catalogue's counters: an option
    # with an enforcer (here a toy one counted in ``malformed``) needs no change there.
    from micros_rt.cli._graphinfo import NodeReport, relay_marking

    toy = QoSOption("toy_check", "subscribe", "bool", "toy", enforcer="toy", counter="malformed")
    monkeypatch.setattr(options, "OPTIONS", OPTIONS + (toy,))
    assert drop_counters()[-1] == "malformed"
    report = NodeReport("/r", "http://x/", "micros_rt", info={"relay": {"graph": "b", "imports": [
        {"outside": "/a/t", "local": "/a/t", "origin": "a", "counters": {"received": 2, "published": 1, "malformed": 1}}]}})
    marking = relay_marking(report, "/a/t", publisher=True)
    assert marking is not None and marking["description"].endswith("published 1 of 2 received (malformed 1)")


def test_the_bridges_key_lists_follow_the_catalogue() -> None:
    assert set(mcu_config._TO_QOS) == {o.name for o in OPTIONS if options.MCU_TO in o.applies}
    assert "deadline" in mcu_config._FROM_QOS and "deadline" not in mcu_config._TO_QOS


def test_a_toy_option_is_one_entry(monkeypatch: pytest.MonkeyPatch) -> None:
    # Adding an option: a field on its class and one catalogue entry (plus an enforcer and a DDS builder
    # when it has them). Everything below comes from the entry: validation with its own rule in words, the
    # XML-RPC/YAML form, the known keys of from_dict, the CLI's and the graph's words.
    def _at_most_ten(value: float) -> None:
        if value > 10.0:
            raise QoSValueError(f"max_hold={value!r} is invalid: at most 10 s")

    toy = QoSOption("max_hold", "subscribe", "duration", "toy: seconds a message may be held", check=_at_most_ten,
                    words=lambda v: f"held at most {v:g} s" if v else None, short=lambda v: f"hold {v:g}" if v else None)

    @dataclasses.dataclass(frozen=True)
    class ToySubscribe(SubscribeQoSOptions):
        max_hold: float = 0.0

    plain_reader = mapping.reader_qos(SubscribeQoSOptions(), queue_size=1)
    monkeypatch.setattr(options, "OPTIONS", OPTIONS + (toy,))
    monkeypatch.setitem(options.OPTION_CLASSES, "subscribe", ToySubscribe)
    monkeypatch.setattr(ToySubscribe, "_KEYS", options._field_keys(ToySubscribe, "subscribe"))

    value = ToySubscribe(max_hold=2)
    assert value.max_hold == 2.0 and value.to_dict()["max_hold"] == 2.0
    assert getattr(ToySubscribe.from_dict({"max_hold": 3}, source="t"), "max_hold") == 3.0
    with pytest.raises(QoSValueError, match="at most 10 s"):
        ToySubscribe(max_hold=11)
    with pytest.raises(QoSValueError, match="max_hold"):  # a known option now, listed in the error
        ToySubscribe.from_dict({"no_such": 1}, source="t")
    assert "held at most 2 s" in describe(value.to_dict(), "subscribe")
    assert "hold 2" in describe(value.to_dict(), "subscribe", short=True)
    # no DDS policy: the reader's Qos is that of the same options without the toy
    assert mapping.reader_qos(value, queue_size=1) == plain_reader
