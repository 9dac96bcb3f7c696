"""``micros-rt topic``: the topics of ROS 1 and ROS 2 together (``list``), which protocol and QoS each link of a
topic uses (``info``), and its latency (``latency``)."""

from __future__ import annotations

import argparse
import concurrent.futures
import importlib
import json
import logging
import math
import os
import sys
import time
from typing import Any, Dict, List, Mapping, Optional, Tuple

from . import CommandError
from ._args import ArgumentParser, dispatch
from ._bothgraph import BOTH, ROS1, ROS2, Both, Ros1View, list_main
from ._bothinfo import MICROS_RT as MICROS_RT_EP
from ._bothinfo import RELAY, carriage, dds_endpoints, dds_links, dds_topic, endpoint_words
from ._ddsgraph import DEFAULT_WAIT, NAMES_WAIT, discover
from ._graphinfo import GraphSnapshot, Master, NodeReport, probe_all, resolve_topic, snapshot

__all__ = ["main", "format_info", "info_data", "latency_report", "format_latency"]


def main(argv: List[str]) -> int:
    """``micros-rt topic <command> ...``."""
    intro = "a command-line tool for ROS 1 and ROS 2 topics and the links and latency of micros_rt topics."
    return dispatch("micros-rt topic", intro, {
        "list": (lambda rest: list_main("micros-rt topic list", "topics", rest),
                 "list ROS 1 topics (master) and ROS 2 topics (DDS discovery), each marked ROS 1, ROS 2 or ROS 1+2"),
        "info": (info_main, "print a topic of ROS 1, ROS 2 or both: its nodes, every link (protocol, QoS, why not "
                            "DDS) and what a relay carries of it between the two"),
        "latency": (latency_main, "measure a topic's rate, latency, drops, deadline and budget misses"),
    }, argv)


# --------------------------------------------------------------------------- info

def info_main(argv: List[str]) -> int:
    parser = ArgumentParser(
        prog="micros-rt topic info", usage="%(prog)s [--json] [--wait SEC] /topic",
        description="Print a topic of ROS 1, ROS 2 or both: its ROS 1 publishers and subscribers (the master) and "
                    "every publisher->subscriber link with its protocol (SHM, DDS or TCPROS), both sides' QoS, the "
                    "transport priority and, between two micros_rt nodes, why DDS was declined; its ROS 2 readers "
                    "and writers (DDS discovery on ROS_DOMAIN_ID for --wait seconds) and their DDS links; and what a "
                    "micros-rt relay carries of it between ROS 1 and ROS 2.")
    parser.add_argument("topic", help="topic name, e.g. /chatter")
    parser.add_argument("--json", action="store_true", help="print JSON (for scripts) instead of text")
    parser.add_argument("--wait", type=float, default=DEFAULT_WAIT, metavar="SEC",
                        help=f"seconds of DDS discovery (default {DEFAULT_WAIT:g}); naming the ROS 2 nodes of the topic "
                             f"takes up to {NAMES_WAIT:g} s more")
    args = parser.parse_args(argv)
    if args.wait < 0:
        raise CommandError("--wait must not be negative", code=2)
    data = info_data(Master(), resolve_topic(args.topic), wait=args.wait)
    print(json.dumps(data, indent=2) if args.json else format_info(data))
    for note in data["notes"]:
        print(f"micros-rt topic info: note: {note}", file=sys.stderr)
    return 0


def _ros1_side(master: Master, topic: str) -> Tuple[Optional[GraphSnapshot], str, str]:
    """(the master's snapshot of ``topic`` or None, its run_id, why None)."""
    try:
        snap = snapshot(master, [topic])
    except CommandError as exc:
        return None, "", str(exc)
    try:
        run_id = str(master.call("getParam", "/run_id"))
    except CommandError:
        run_id = ""
    return snap, run_id, ""


def info_data(master: Master, topic: str, *, wait: float = DEFAULT_WAIT,
              env: Mapping[str, str] = os.environ) -> Dict[str, Any]:
    """What ``topic info`` shows, as plain data (also its ``--json`` output): the master's side and DDS discovery's,
    asked at once."""
    with concurrent.futures.ThreadPoolExecutor(max_workers=1) as pool:
        ros1 = pool.submit(_ros1_side, master, topic)
        view = discover(wait, env, name_topics={dds_topic(topic)})
        snap, run_id, ros1_note = ros1.result()
    both = Both(Ros1View(snap is not None, ros1_note, uri=master.uri, run_id=run_id), view)
    endpoints = dds_endpoints(view, topic, both.ours) if view.available else []
    in_master = snap is not None and (topic in snap.types or topic in snap.publishers or topic in snap.subscribers)
    if not in_master and not endpoints:
        where = [] if snap is None else ["the ROS 1 master"]
        where += [f"DDS discovery ({view.wait:g} s on domain {view.domain})"] if view.available else []
        notes = " ".join(n + "." for n in both.notes())
        raise CommandError(f"unknown topic {topic} (no publisher or subscriber of it in {' or '.join(where) or 'either graph'}"
                           f"; see micros-rt topic list){' ' + notes if notes else ''}")
    reports: Dict[str, NodeReport] = dict(snap.nodes) if snap is not None else {}
    relays = sorted({e["node"] for e in endpoints if e["kind"] == RELAY} - set(reports))
    if relays and snap is not None:  # a relay that carries the topic under another name in ROS 1: ask it too
        reports.update(probe_all(master, relays))
    carried = carriage(reports, topic)
    for c in carried:  # where it comes from and where it goes, on the ROS 2 side of this name
        if c["ros2"] == topic:
            ends = [e["node"] for e in endpoints if e["kind"] != RELAY and e["writer"] == (c["direction"] == "from ROS 2")]
            c["ros2_nodes"] = sorted(set(ends))
            if ends:
                c["description"] += (f"; written in ROS 2 by {', '.join(sorted(set(ends)))}" if c["direction"] ==
                                     "from ROS 2" else f"; read in ROS 2 by {', '.join(sorted(set(ends)))}")
    on_ros1 = in_master or any(e["kind"] in (MICROS_RT_EP, RELAY) for e in endpoints)
    side = (ROS1 if not endpoints else BOTH if on_ros1 else ROS2)
    data: Dict[str, Any] = {
        "topic": topic, "side": side,
        "type": (snap.types.get(topic) if snap is not None else None) or "unknown",
        "ros2_types": sorted({e["type"] for e in endpoints}),
        "publishers": [], "subscribers": [], "links": [],
        "ros2_writers": [e for e in endpoints if e["writer"]], "ros2_readers": [e for e in endpoints if not e["writer"]],
        "dds_links": dds_links(endpoints), "carried": carried, "notes": both.notes(),
        "dds": {"domain": view.domain, "wait": view.wait} if view.available else None,
        "ros1_unknown": None if snap is not None else ros1_note or "the ROS 1 master cannot be reached",
    }
    if in_master and snap is not None:
        data["publishers"] = [snap.endpoint(n, topic, publisher=True) for n in sorted(snap.publishers.get(topic, []))]
        data["subscribers"] = [snap.endpoint(n, topic, publisher=False)
                               for n in sorted(snap.subscribers.get(topic, []))]
        data["links"] = [link.to_dict() for link in snap.links]
        for ep in data["publishers"] + data["subscribers"]:
            ways = [c["description"] for c in carried if c["relay"] == ep["node"]]
            if ways:
                ep["ros2_carriage"] = ways
    return data


def format_info(data: Dict[str, Any]) -> str:
    """The text form of :func:`info_data` (rostopic info's layout, plus the links, the ROS 2 side and what relays
    carry between the two)."""
    data = {"side": ROS1, "ros2_types": [], "ros2_writers": [], "ros2_readers": [], "dds_links": [], "carried": [],
            "dds": None, **data}   # a ROS 1 view alone (no DDS side asked) prints as rostopic info's layout
    ros2_type = ", ".join(data["ros2_types"])
    if data["side"] == ROS2:
        lines = [f"Type: {ros2_type} (ROS 2)", "Side: ROS 2 only (not in the ROS 1 master)", ""]
    else:
        lines = [f"Type: {data['type']}" + (f" (ROS 2: {ros2_type})" if ros2_type else ""),
                 f"Side: {data['side']}", ""]
    sides = {}
    for title, key in (("Publishers", "publishers"), ("Subscribers", "subscribers")):
        if data["side"] == ROS2:
            break
        if data.get("ros1_unknown"):  # the master away: its side is not known, not empty
            lines += [f"{title}: unknown (the ROS 1 master's list: {data['ros1_unknown']})", ""]
            continue
        lines.append(f"{title}:" if data[key] else f"{title}: None")
        for ep in data[key]:
            sides[(key, ep["node"])] = ep["description"]
            lines.append(f" * {ep['node']} ({ep['uri'] or 'unknown URI'})  [{ep['kind']}] {ep['description']}")
            if ep.get("relay"):
                lines.append(f"     {ep['relay']['description']}")
            for words in ep.get("ros2_carriage", []):
                lines.append(f"     {words}")
            if ep.get("paced"):
                lines.append(f"     {ep['paced']['description']}")
        lines.append("")
    if data["dds"] is not None and (data["ros2_writers"] or data["ros2_readers"] or data["side"] != ROS1):
        lines.append(f"ROS 2 side (DDS {dds_topic(data['topic'])}, domain {data['dds']['domain']}):")
        for title, key in (("writers", "ros2_writers"), ("readers", "ros2_readers")):
            lines.append(f" {title}:" if data[key] else f" {title}: None")
            for ep in data[key]:
                lines.append(f" * {ep['node']}  {endpoint_words(ep, data['carried'])}")
        lines.append("")
    if data["carried"] and not all(any(c["description"] in ep.get("ros2_carriage", []) for ep in data["publishers"]
                                       + data["subscribers"]) for c in data["carried"]):
        lines.append("Carried between ROS 1 and ROS 2:")
        lines += [f" * {c['description']}" for c in data["carried"]]
        lines.append("")
    lines.append("Links:" if data["links"] or data["dds_links"] else "Links: None")
    for link in data["links"]:
        prio = link["transport_priority"] or "n/a (stock publisher)"
        state = "" if link["matched"] is not False else " (DDS discovery not matched yet)"
        lines.append(f" * {link['publisher']} -> {link['subscriber']}: {link['protocol']}{state}, "
                     f"transport priority {prio}")
        lines.append(f"     publisher QoS:  {sides.get(('publishers', link['publisher']), 'unknown')}")
        lines.append(f"     subscriber QoS: {sides.get(('subscribers', link['subscriber']), 'unknown')}")
        if link["reason"]:
            label = ("why SHM" if link["protocol"] == "SHM" else "DDS declined" if link["verdict"] else
                     "why TCPROS")
            lines.append(f"     {label}: {link['reason']}")
        for marking in link.get("relayed", []):
            lines.append(f"     {marking['summary']}")
    for link in data["dds_links"]:
        state = "" if link["matched"] else f" not matched: {link['reason']}"
        lines.append(f" * {link['publisher']} ({link['publisher_kind']}) -> {link['subscriber']} "
                     f"({link['subscriber_kind']}): DDS{state}")
    return "\n".join(lines).rstrip("\n")


# --------------------------------------------------------------------------- latency

def latency_main(argv: List[str]) -> int:
    parser = ArgumentParser(
        prog="micros-rt topic latency", usage="%(prog)s [--count N] [--json] [--plot FILE.png] [--deadline SEC] /topic",
        description="Subscribe to a topic with micros_rt (DDS where the publisher can, else TCPROS) and show, "
                    "refreshed in place, its rate and latency (p50/p99/max) from DDS source timestamps or "
                    "Header stamps, drops, deadline misses and latency-budget misses. Ctrl-C, --count or "
                    "--timeout stop it and print a report.")
    parser.add_argument("topic", help="topic name, e.g. /chatter")
    parser.add_argument("-n", "--count", type=int, default=0, metavar="N", help="stop after N messages")
    parser.add_argument("--json", action="store_true", help="print only the final report, as JSON")
    parser.add_argument("--plot", metavar="FILE.png", help="write a latency histogram to FILE.png")
    parser.add_argument("--timeout", type=float, default=0.0, metavar="SEC",
                        help="stop after SEC seconds (exit 1 when fewer than --count messages came)")
    parser.add_argument("--deadline", type=float, default=0.0, metavar="SEC",
                        help="count deadline misses: gaps longer than SEC seconds between messages")
    parser.add_argument("-v", "--verbose", action="store_true",
                        help="also print micros_rt's warnings (QoS mismatches, each deadline miss)")
    args = parser.parse_args(argv)
    if args.count < 0 or args.timeout < 0 or args.deadline < 0:
        raise CommandError("--count, --timeout and --deadline must not be negative", code=2)
    topic = resolve_topic(args.topic)
    type_name = Master().topic_types().get(topic)
    if type_name is None:
        raise CommandError(f"unknown topic {topic} (no publisher has advertised it; see rostopic list)")
    return _measure(topic, type_name, args)


class Arrivals:
    """Message count and first/last arrival (monotonic seconds), updated on the delivery thread."""

    def __init__(self) -> None:
        self.n = 0
        self.first = self.last = 0.0

    def on_message(self, _msg: Any) -> None:
        now = time.monotonic()
        if not self.n:
            self.first = now
        self.n += 1
        self.last = now


def _measure(topic: str, type_name: str, args: argparse.Namespace) -> int:
    import roslib.message

    data_class = roslib.message.get_message_class(type_name)
    if data_class is None:
        raise CommandError(f"topic {topic}: cannot load message type {type_name} (is its package installed?)")
    import micros_rt

    micros_rt.init_node("micros_rt_topic_latency", anonymous=True, disable_signals=True, disable_rosout=True)
    if not args.verbose:
        # the report counts deadline misses and names each link's protocol; per-event warnings would
        # break the line refreshed in place (init_node reset rospy's loggers, so set it after)
        logging.getLogger("rosout.micros_rt").setLevel(logging.ERROR)
    arrivals = Arrivals()

    nh = micros_rt.NodeHandle()
    if args.deadline:
        qos = micros_rt.SubscribeQoSOptions(deadline=args.deadline, ordered_by_sending_timestamp=False)
        sub = nh.subscribe_with_qos(topic, data_class, arrivals.on_message, None, qos)
    else:
        sub = nh.subscribe(topic, data_class, arrivals.on_message, None)
    live = not args.json
    tty = sys.stdout.isatty()
    start = time.monotonic()
    last_show, last_n = start, 0
    try:
        while not micros_rt.is_shutdown():
            now = time.monotonic()
            if args.count and arrivals.n >= args.count:
                break
            if args.timeout and now - start > args.timeout:
                break
            if live and now - last_show >= 1.0:
                rate = (arrivals.n - last_n) / (now - last_show)
                last_show, last_n = now, arrivals.n
                line = format_live(latency_report(topic, type_name, sub, arrivals), rate)
                print(f"\r{line}\033[K" if tty else line, end="" if tty else "\n", flush=True)
            time.sleep(0.02)
    except KeyboardInterrupt:
        pass
    report = latency_report(topic, type_name, sub, arrivals)
    samples = [s * 1e3 for s in list(sub.latency.samples)]
    micros_rt.shutdown()
    if live and tty:
        print()
    print(json.dumps(report, indent=2) if args.json else format_latency(report))
    if args.plot:
        marks = {k: v for k, v in report["latency_ms"].items() if k in ("p50", "p99") and v is not None}
        write_histogram(args.plot, samples, f"{topic} ({report['timestamps']}): {len(samples)} messages", marks)
    if args.count and report["messages"] < args.count:
        print(f"micros-rt topic latency: only {report['messages']} of {args.count} messages on {topic} within "
              f"{args.timeout:g} s", file=sys.stderr)
        return 1
    return 0


def _num(value: float, scale: float = 1.0) -> Optional[float]:
    return None if value is None or math.isnan(value) or math.isinf(value) else round(value * scale, 4)


def latency_report(topic: str, type_name: str, sub: Any, arrivals: "Arrivals") -> Dict[str, Any]:
    """The numbers ``topic latency`` shows, from the micros_rt Subscriber's own statistics."""
    n = arrivals.n
    span = arrivals.last - arrivals.first
    lat = sub.latency.summary()
    stats = sub.statistics()
    transports = sub.connection_transports()
    protocols = set(transports.values())
    if n == 0:
        stamps = "none yet"
    elif lat["count"] == 0:
        stamps = "none (no DDS link and no Header stamp)"
    elif protocols == {"DDS"} or not getattr(sub.data_class, "_has_header", False):
        stamps = "DDS source timestamps"
    elif "DDS" in protocols:
        stamps = "DDS source timestamps and Header stamps"
    else:
        stamps = "Header stamps"
    drops = {"queue_full": stats.dropped_queue_full, "expired": stats.dropped_expired,
             "filtered": stats.dropped_filtered, "out_of_order": stats.dropped_out_of_order,
             "malformed": stats.malformed}
    drops["total"] = sum(drops.values())
    return {
        "topic": topic, "type": type_name, "messages": n, "rate_hz": _num((n - 1) / span) if n > 1 and span > 0
        else None, "transports": transports, "timestamps": stamps,
        "latency_ms": {"count": lat["count"], "mean": _num(lat["mean"], 1e3), "p50": _num(lat["p50"], 1e3),
                       "p99": _num(lat["p99"], 1e3), "max": _num(lat["max"], 1e3)},
        "drops": drops, "deadline_misses": stats.deadline_missed,
        "budget_misses": lat["budget_misses"], "budget_checked": lat["budget_checked"],
    }


def _ms(value: Optional[float]) -> str:
    return "-" if value is None else f"{value:.3f} ms"


def format_live(report: Dict[str, Any], rate: float) -> str:
    """One refreshed status line."""
    lat = report["latency_ms"]
    links = ",".join(sorted(set(report["transports"].values()))) or "no publisher yet"
    return (f"{report['topic']} [{links}] {report['messages']} msgs  rate {rate:.1f} Hz  latency p50 {_ms(lat['p50'])}"
            f"  p99 {_ms(lat['p99'])}  max {_ms(lat['max'])}  drops {report['drops']['total']}  deadline misses "
            f"{report['deadline_misses']}  budget misses {report['budget_misses']}")


def format_latency(report: Dict[str, Any]) -> str:
    """The final report as text."""
    lat = report["latency_ms"]
    rate = "-" if report["rate_hz"] is None else f"{report['rate_hz']:.2f} Hz"
    links = ", ".join(f"{uri} {proto}" for uri, proto in sorted(report["transports"].items())) or "none"
    return "\n".join([
        f"topic:     {report['topic']} ({report['type']})",
        f"links:     {links}",
        f"messages:  {report['messages']}, rate {rate}",
        f"latency:   p50 {_ms(lat['p50'])}, p99 {_ms(lat['p99'])}, max {_ms(lat['max'])}, mean {_ms(lat['mean'])}"
        f" ({lat['count']} of {report['messages']} measured, from {report['timestamps']})",
        f"drops:     {report['drops']['total']} ("
        + ", ".join(f"{kind.replace('_', ' ')} {n}" for kind, n in report["drops"].items() if kind != "total") + ")",
        f"deadline misses: {report['deadline_misses']}, latency budget misses: {report['budget_misses']} of "
        f"{report['budget_checked']} checked",
    ])


def write_histogram(path: str, samples_ms: List[float], title: str, marks: Dict[str, float]) -> None:
    """A latency histogram (matplotlib, no display needed) with vertical lines at ``marks`` (name -> ms)."""
    try:
        # through importlib: matplotlib has no type stubs (and is only needed here)
        matplotlib = importlib.import_module("matplotlib")
        matplotlib.use("Agg")
        plt = importlib.import_module("matplotlib.pyplot")
    except ImportError as exc:
        raise CommandError(f"--plot needs matplotlib ({exc}); apt-get install python3-matplotlib") from None
    fig, ax = plt.subplots(figsize=(8, 4.5))
    if samples_ms:
        ax.hist(samples_ms, bins=min(80, max(20, len(samples_ms) // 5)), color="#1f77b4")
        for (name, value), style in zip(marks.items(), ("--", ":", "-.")):
            ax.axvline(value, color="#e66100", linestyle=style, label=f"{name} {value:.3f} ms")
        if marks:
            ax.legend()
    else:
        ax.text(0.5, 0.5, "no latency samples", ha="center", va="center", transform=ax.transAxes)
    ax.set_xlabel("latency (ms)")
    ax.set_ylabel("messages")
    ax.set_title(title)
    fig.tight_layout()
    try:
        fig.savefig(path, dpi=100)
    except OSError as exc:
        raise CommandError(f"cannot write {path}: {exc.strerror or exc}") from None
    finally:
        plt.close(fig)
