"""RAFT is the flow every entry point flies unless told otherwise (the RAFT issue), and each one's --help says so."""

from __future__ import annotations

import pytest

from companion.flow.registry import DEFAULT_FLOW, parse_backend


def _help(main, capsys) -> str:
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    return " ".join(capsys.readouterr().out.split())      # argparse wraps lines


def test_the_default_flow_is_raft_everywhere_and_the_help_says_so(capsys):
    from companion.__main__ import build_parser
    from tools.eval_flights import _parser
    from tools.launch import main as sitl_main
    from tools.sweep_executors import FlightSettings

    assert DEFAULT_FLOW == "raft" and parse_backend(DEFAULT_FLOW) == ("raft", {})
    assert build_parser().parse_args([]).flow == "raft"
    assert _parser().parse_args([]).flow == "raft"
    assert FlightSettings().flow == "raft"
    assert "(default raft" in _help(build_parser().parse_args, capsys)
    assert "(default raft" in _help(_parser().parse_args, capsys)
    assert "(default raft" in _help(sitl_main, capsys)
    # DIS stays selectable
    assert build_parser().parse_args(["--flow", "dis:fine"]).flow == "dis:fine"
