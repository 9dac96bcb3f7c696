"""The transport contract (:mod:`contract.checks`) for TCPROS, in a micros_rt node of its own (TCPROS needs a
master): ``.venv/bin/python tests/contract/tcpros_child.py`` with ROS_MASTER_URI set. Prints one JSON line per
check: ``{"check": name, "ok": bool, "error": text}``; exits 0 when every check that applies passed."""

from __future__ import annotations

import json
import sys
import time
import traceback
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import micros_rt  # noqa: E402

from contract.checks import CHECKS, check_malformed_wire_input_raises_a_micros_rt_error_in_words  # noqa: E402
from contract.pairs import tcpros_pair  # noqa: E402

#: rospy's own receive thread decodes TCPROS (and logs and drops what does not deserialize): no micros_rt decoder
NOT_APPLICABLE = {check_malformed_wire_input_raises_a_micros_rt_error_in_words:
                  "TCPROS is decoded by rospy's receive thread, not by micros_rt"}


def main() -> int:
    micros_rt.init_node("contract_tcpros", argv=[sys.argv[0]])
    failed = 0
    for check in CHECKS:
        t0 = time.monotonic()
        if check in NOT_APPLICABLE:
            print(json.dumps({"check": check.__name__, "ok": None, "error": NOT_APPLICABLE[check]}) + "\n", end="", flush=True)
            continue
        pair = tcpros_pair()
        try:
            check(pair)
            result = {"check": check.__name__, "ok": True, "error": ""}
        except BaseException as exc:  # reported to the test, which fails on it
            failed += 1
            result = {"check": check.__name__, "ok": False,
                      "error": f"{type(exc).__name__}: {exc}\n{traceback.format_exc()[-1500:]}"}
        finally:
            pair.writer.close()
            pair.reader.close()
        result["seconds"] = round(time.monotonic() - t0, 3)
        sys.stdout.write(json.dumps(result) + "\n")  # one write: another thread's log line cannot land inside it
        sys.stdout.flush()
    micros_rt.shutdown("contract done")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
