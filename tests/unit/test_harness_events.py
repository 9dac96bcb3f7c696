"""tests/harness.py split_events: a peer's stdout line into events, when another thread of the peer wrote into it.

Stop 50's CI lost a service response event: the peer's ``print`` wrote the JSON and its newline in two calls, and
rospy's logger wrote an INFO line between them, so the line was JSON followed by log text, and all of it was kept
as raw text."""

from __future__ import annotations

import harness


def test_a_json_event_followed_by_a_log_line_keeps_both() -> None:
    line = ('{"event": "response", "label": "true", "fields": {"success": true}}'
            '[INFO] [1795855630.449410]: micros_rt: this node watches DDS domain 141')
    assert harness.split_events(line) == [
        {"event": "response", "label": "true", "fields": {"success": True}},
        {"event": "_raw", "line": "[INFO] [1795855630.449410]: micros_rt: this node watches DDS domain 141"}]


def test_two_events_on_one_line_are_two_events() -> None:
    assert harness.split_events('{"event": "a"}{"event": "b", "n": 2}') == [{"event": "a"}, {"event": "b", "n": 2}]


def test_text_that_is_not_an_event_stays_raw() -> None:
    for line in ('[INFO] got {"event": "x"}', "{not json", "[1, 2]", "plain text", '{"event": "a"'):
        assert harness.split_events(line) == [{"event": "_raw", "line": line}], line


def test_an_event_alone_is_itself() -> None:
    assert harness.split_events('{"event": "done", "ok": 3}') == [{"event": "done", "ok": 3}]
