"""The report shows a run's resolved protocol as ``dotted.key = value`` lines, each list on
one line (what ``--set`` takes), not JSON's one number a line."""

from __future__ import annotations

import json

from ffexp.protocol import RunProtocol
from ffexp.report import _dotted_lines


def test_resolved_protocol_lines_are_set_forms_with_lists_on_one_line() -> None:
    proto = RunProtocol(name="x")
    text = _dotted_lines(json.loads(proto.model_dump_json()))
    lines = text.splitlines()
    kp = [x for x in lines if x.startswith("align.kp = ")]
    assert kp == [f"align.kp = {json.dumps(list(proto.align.kp))}"]
    assert 'name = "x"' in lines
    # every line is one key and its whole value: as many lines as leaves
    assert all(" = " in x for x in lines)
    assert not any(x.strip() in ("[", "]") or x.strip().rstrip(",").replace(".", "").isdigit()
                   for x in lines)
