"""``micros-rt profile check FILE``: validate a YAML QoS profile as the library reads it (errors name the
file and line) and, when a ROS master answers, show which live topics each rule gives its QoS to."""

from __future__ import annotations

from typing import Any, Dict, List, Mapping, Sequence, Union

from . import CommandError
from ._args import ArgumentParser, dispatch
from ._graphinfo import Master, describe_publisher_qos, describe_subscriber_qos

__all__ = ["main", "rule_matches"]


def main(argv: List[str]) -> int:
    """``micros-rt profile check FILE``."""
    return dispatch("micros-rt profile", "a command-line tool for YAML QoS profiles (MICROS_RT_QOS_PROFILE).", {
        "check": (check_main, "validate a profile and show which live topics each rule matches"),
    }, argv)


def check_main(argv: List[str]) -> int:
    """``micros-rt profile check [--offline] FILE``."""
    parser = ArgumentParser(
        prog="micros-rt profile check", usage="%(prog)s [--offline] FILE.yaml",
        description="Validate a YAML QoS profile exactly as micros_rt.init_node reads it (an error names the "
                    "file and line). With a ROS master running, list for each rule the live topics it matches "
                    "(an exact name beats a pattern; the longest pattern wins) and the QoS they would get.")
    parser.add_argument("file", help="the profile, e.g. qos.yaml")
    parser.add_argument("--offline", action="store_true", help="do not ask the ROS master for live topics")
    args = parser.parse_args(argv)
    from ..exceptions import ProfileError
    from ..qos import QoSProfile

    try:
        profile = QoSProfile.load(args.file)
    except ProfileError as exc:
        raise CommandError(str(exc)) from None
    print(f"{args.file}: valid ({_plural(len(profile.publishers), 'publisher rule')}, "
          f"{_plural(len(profile.subscribers), 'subscriber rule')}"
          + (f", {_plural(len(profile.links), 'link')})" if profile.links else ")"))
    live: Dict[str, Dict[str, List[str]]] = {}
    if not args.offline:
        master = Master(timeout=3.0)
        try:
            pubs, subs = master.system_state()
            live = {"publishers": pubs, "subscribers": subs}
        except CommandError:
            print(f"no ROS master at {master.uri}: live topics not matched (start the graph, or --offline)")
    for section, describe in (("publishers", describe_publisher_qos), ("subscribers", describe_subscriber_qos)):
        rules = profile.publishers if section == "publishers" else profile.subscribers
        if not rules:
            continue
        print(f"\n{section}:")
        for key, options in rules.items():
            if section == "subscribers":
                order = profile.subscribe_transports(key)
                transports = f"; transports offered in order: {', '.join(order)}" if order else ""
            else:
                order = profile.advertise_transports(key)
                transports = f"; transports served: {', '.join(order)}" if order else ""
            print(f"  {key}: {describe(options.to_dict())}{transports}")
            if section in live:
                matched = rule_matches(profile, section, key, live[section])
                for topic, (nodes, shadow) in matched.items():
                    who = ", ".join(nodes)
                    print(f"    {'(overridden by ' + repr(shadow) + ')' if shadow else 'matches'} {topic}  [{who}]")
                if not matched:
                    print(f"    matches no live {section[:-1]} topic")
    if profile.links:
        from ..qos.links import send_buffer_below_high

        print("\nlinks (TCPROS connections of topics below HIGH to peers across them are paced; DDS writers below "
              "HIGH get a small UDP send buffer):")
        for link in profile.links:
            print(f"  {link.describe()}: topics below HIGH share {link.paced_rate / 1e6:g} Mbit/s")
        print(f"  DDS writers below HIGH: a send buffer of {send_buffer_below_high(profile.links):,} bytes "
              f"(the slowest link's)")
    return 0


def _plural(n: int, noun: str) -> str:
    return f"{n} {noun}{'' if n == 1 else 's'}"


def rule_matches(profile: Any, section: str, key: str,
                 endpoints: Mapping[str, Sequence[str]]) -> Dict[str, "tuple[List[str], Union[str, None]]"]:
    """Live topics (with their nodes) whose names rule ``key`` matches: topic -> (nodes, the key of the rule
    that wins instead, or None when this one applies). Uses the library's own lookup."""
    from ..qos.topic_rules import TopicPattern

    rules = profile.publishers if section == "publishers" else profile.subscribers
    lookup = profile.advertise_options if section == "publishers" else profile.subscribe_options
    mine = rules[key]
    pattern = TopicPattern.parse(key)  # the profile's own matcher: names, globs and ^...$ expressions
    out: Dict[str, "tuple[List[str], Union[str, None]]"] = {}
    for topic in sorted(endpoints):
        if not pattern.matches(topic):
            continue
        winner = lookup(topic)
        shadow = None if winner is mine else next((k for k, v in rules.items() if v is winner), "?")
        out[topic] = (sorted(endpoints[topic]), shadow)
    return out
