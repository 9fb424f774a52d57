"""Python for those who want it (issue 27, point 4), without a browser: the clients' reference the
Program tab shows and completes, read from asibot.client, and how a program's Python error is
told: one sentence with its line and a single full stop, the traceback without the machine's paths.
"""

from __future__ import annotations

import inspect
import os
import textwrap

import pytest

from asibot.client import CartesianClient, NavClient
from asibot.testing import wait_until
from asibot.web import reference
from asibot.web.runner import Limits, ProgramRunner, RunResult
from asibot.web.tracebacks import Files, full_stop, read_error, without_stop

# --- the reference ---------------------------------------------------------------------------------


def public_methods(cls: type) -> set[str]:
    return {n for n in dir(cls) if not n.startswith("_") and inspect.isfunction(inspect.getattr_static(cls, n))}


@pytest.mark.parametrize("cls", [CartesianClient, NavClient])
def test_the_reference_lists_every_method_a_program_calls_and_only_those(cls):
    client = next(c for c in reference.build()["clients"] if c["name"] == cls.__name__)
    names = [m["name"] for m in client["methods"]]
    assert len(names) == len(set(names))
    assert set(names) == public_methods(cls)
    assert "on" not in names and not any(n.startswith("_") for n in names)   # `on` is a service's, not a program's
    assert names[0] == "open"                                                # the base's first: open, close ...
    assert client["doc"] == " ".join(inspect.getdoc(cls).split("\n\n")[0].split())


def test_a_method_has_its_signature_call_summary_and_first_paragraph_from_its_docstring():
    methods = {m["name"]: m for c in reference.build()["clients"] if c["name"] == "CartesianClient" for m in c["methods"]}
    movl = methods["movl"]
    assert movl["signature"] == "movl(point: Sequence[float], *, duration: float | None = None, speed: float | None = None) -> float"
    assert movl["call"] == "movl(point, *, duration=None, speed=None)" and movl["returns"] == "float"
    assert movl["summary"] == movl["doc"] == inspect.getdoc(CartesianClient.movl)
    act = methods["act"]
    assert act["summary"].startswith('Gripper "open" or "close"; returns once the fingers') and act["summary"].endswith("}.")
    assert act["doc"].endswith("after 4 s.") and act["summary"] != act["doc"]       # first sentence; first paragraph
    assert methods["grip"]["call"] == "grip(close=True)" and methods["grip"]["returns"] == "bool"
    assert methods["release"]["summary"] == "Release the emergency stop."          # not the gripper
    wait = methods["wait"]
    assert wait["summary"] == "Block until the motion ends." and "Timeout" in wait["doc"]
    assert all(m["doc"] for m in methods.values()), [n for n, m in methods.items() if not m["doc"]]


def test_a_docstring_change_is_in_the_reference_at_once(monkeypatch):
    """One source of truth: the reference reads the client, it keeps no copy of its own."""
    def grip(self, close: bool = True) -> bool:
        """Squeeze. Then more."""
    monkeypatch.setattr(CartesianClient, "grip", grip)
    reference._built.cache_clear()
    try:
        methods = {m["name"]: m for m in reference.build()["clients"][0]["methods"]}
        assert methods["grip"]["summary"] == "Squeeze." and methods["grip"]["doc"] == "Squeeze. Then more."
    finally:
        monkeypatch.undo()
        reference._built.cache_clear()


@pytest.mark.parametrize("client, missing, meant", [
    ("CartesianClient", "open_gripper", ["act", "grip"]),
    ("CartesianClient", "close_gripper", ["act", "grip"]),
    ("CartesianClient", "release_gripper", []),       # never the emergency stop's release
    ("NavClient", "goto_place", ["goto"]),
    ("CartesianClient", "fly", []),
])
def test_a_missing_method_suggests_what_was_meant(client, missing, meant):
    assert reference.guess(client, missing) == meant


def test_the_reference_route_answers_the_page_and_refuses_other_origins(web):
    client = web[0]
    reply = client.get("/api/client-reference")
    assert reply.status_code == 200 and reply.json() == reference.build()
    names = [c["name"] for c in reply.json()["clients"]]
    assert names == ["CartesianClient", "NavClient"] and reply.json()["module"] == "asibot.client"
    # Another site's page (Fetch Metadata, or its Origin) and a rebound DNS name get nothing.
    assert client.get("/api/client-reference", headers={"Sec-Fetch-Site": "cross-site"}).status_code == 403
    assert client.get("/api/client-reference", headers={"Origin": "http://evil.example"}).status_code == 403
    assert client.get("/api/client-reference", headers={"Host": "evil.example:8080"}).status_code == 400
    # A program named "reference" stays a program.
    assert client.post("/api/programs", json={"name": "reference"}).status_code == 200
    assert client.get("/api/programs/reference").json()["name"] == "reference"
    assert client.delete("/api/programs/reference").status_code == 200


# --- the error sentence ----------------------------------------------------------------------------
LIB = "/opt/asibot/libs/common"
STDLIB = "/usr/lib/python3.11"
SITE = "/opt/venv/lib/python3.11/site-packages"
SINGULARITY = ("The straight line passes a singularity or configuration change at 40 % of the path: "
               "x 0.1 m; use movj for this move or pick an intermediate point.")


@pytest.fixture
def files(tmp_path):
    return Files(tmp_path / "give_me_the_can.py", roots=[LIB, STDLIB, SITE])


def tb(tmp_path, text: str) -> list[str]:
    return textwrap.dedent(text).format(folder=tmp_path, lib=LIB, stdlib=STDLIB, site=SITE).strip("\n").split("\n")


def test_a_refused_motion_is_one_sentence_with_its_line_and_one_full_stop(tmp_path, files):
    lines = tb(tmp_path, f"""\
        hello, robot!
        Traceback (most recent call last):
          File "{{folder}}/give_me_the_can.py", line 7, in <module>
            simCart.movl(above)
          File "{{lib}}/asibot/client.py", line 160, in movl
            return self._call("movl", point=point, duration=duration, speed=speed)["duration"]
                   ^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^^
          File "{{lib}}/asibot/client.py", line 89, in _call
            return bus.call(self._key(verb), body, timeout=_timeout or self.timeout)
          File "{{lib}}/asibot/bus/base.py", line 356, in call
            raise RpcError(code, message)
          File "{{site}}/zenoh/__init__.py", line 12, in get
            pass
        asibot.errors.RpcError: {SINGULARITY}""")
    error = read_error(lines, files)
    assert error is not None and error.line == 7
    assert error.sentence == f"Line 7: {SINGULARITY}"
    assert error.sentence.endswith("point.") and not error.sentence.endswith("..")
    # The runner's reason is followed by the page's full stop ("<program>: <reason>."): it has none.
    assert error.reason == f"failed with an error on line 7: {SINGULARITY[:-1]}"
    assert f"give_me_the_can: {error.reason}.".endswith("intermediate point.")
    assert error.details == [
        "Traceback (most recent call last):",
        '  File "give_me_the_can.py", line 7, in <module>',
        "    simCart.movl(above)",
        '  File "asibot.client", line 160, in movl',
        f"asibot.errors.RpcError: {SINGULARITY}",
    ]
    assert error.taken == len(lines) - 1      # all but "hello, robot!"
    assert not any(p in "\n".join(error.details) for p in (str(tmp_path), LIB, SITE, "/"))


def test_pythons_own_errors_keep_their_class_and_get_a_full_stop(tmp_path, files):
    error = read_error(tb(tmp_path, """\
        Traceback (most recent call last):
          File "{folder}/give_me_the_can.py", line 3, in <module>
            print(x)
                  ^
        NameError: name 'x' is not defined"""), files)
    assert error is not None
    assert error.sentence == "Line 3: NameError: name 'x' is not defined."
    assert error.reason == "failed with an error on line 3: NameError: name 'x' is not defined"
    assert error.details[-3:] == ["    print(x)", "          ^", "NameError: name 'x' is not defined"]


def test_a_syntax_error_has_no_header_and_still_its_line(tmp_path, files):
    error = read_error(tb(tmp_path, """\
          File "{folder}/give_me_the_can.py", line 2
            if x
                ^
        SyntaxError: expected ':'"""), files)
    assert error is not None and error.sentence == "Line 2: SyntaxError: expected ':'." and error.taken == 4
    assert error.details[0] == '  File "give_me_the_can.py", line 2'


def test_an_unknown_client_method_says_what_was_meant(tmp_path, files):
    error = read_error(tb(tmp_path, """\
        Traceback (most recent call last):
          File "{folder}/give_me_the_can.py", line 5, in <module>
            simCart.open_gripper()
            ^^^^^^^^^^^^^^^^^^^^
        AttributeError: 'CartesianClient' object has no attribute 'open_gripper'"""), files)
    assert error is not None
    assert error.sentence == ("Line 5: CartesianClient has no method open_gripper (AttributeError). Did you mean "
                              "act or grip? The Python reference on the Program tab lists its methods.")


def test_a_chain_of_exceptions_is_one_error_the_last_one(tmp_path, files):
    lines = tb(tmp_path, """\
        working
        Traceback (most recent call last):
          File "{folder}/helper.py", line 7, in load
            return json.loads("{{")
                   ^^^^^^^^^^^^^^^
          File "{stdlib}/json/__init__.py", line 346, in loads
            return _default_decoder.decode(s)
          File "{stdlib}/json/decoder.py", line 337, in decode
            obj, end = self.raw_decode(s, idx=_w(s, 0).end())
        json.decoder.JSONDecodeError: Expecting property name enclosed in double quotes: line 1 column 2 (char 1)

        The above exception was the direct cause of the following exception:

        Traceback (most recent call last):
          File "{folder}/give_me_the_can.py", line 5, in <module>
            helper.load()
          File "{folder}/helper.py", line 9, in load
            raise KeyError("k") from e
        KeyError: 'k'""")
    error = read_error(lines, files)
    assert error is not None and error.line == 5 and error.sentence == "Line 5: KeyError: 'k'."
    assert error.taken == len(lines) - 1
    frames = [d for d in error.details if d.startswith("  File")]
    assert frames == ['  File "helper.py", line 7, in load',
                      '  File "json", line 346, in loads',            # where the user's call entered a library
                      '  File "give_me_the_can.py", line 5, in <module>',
                      '  File "helper.py", line 9, in load']          # another file of the user's folder
    assert "The above exception was the direct cause of the following exception:" in error.details


@pytest.mark.parametrize("lines", [[], ["to stderr"], ["Error: no can found"]])
def test_other_ends_are_no_python_error(tmp_path, files, lines):
    assert read_error(lines, files) is None


def test_output_lines_name_files_without_the_machines_paths(tmp_path, files):
    assert files.line(f'  File "{tmp_path}/give_me_the_can.py", line 7, in <module>') == \
        '  File "give_me_the_can.py", line 7, in <module>'
    assert files.line(f'  File "{LIB}/asibot/bus/__init__.py", line 3, in <module>') == '  File "asibot.bus", line 3, in <module>'
    assert files.line('  File "/srv/elsewhere/thing.py", line 1, in f') == '  File "thing.py", line 1, in f'
    assert files.line(f"FileNotFoundError: [Errno 2] No such file or directory: '{tmp_path}/cans.txt'") == \
        "FileNotFoundError: [Errno 2] No such file or directory: 'cans.txt'"


@pytest.mark.parametrize("text, stop, clause", [
    ("Out of reach.", "Out of reach.", "Out of reach"),
    ("name 'x' is not defined", "name 'x' is not defined.", "name 'x' is not defined"),
    ("Really?", "Really?", "Really?"),
    ("and so on...", "and so on...", "and so on..."),
])
def test_one_full_stop(text, stop, clause):
    assert full_stop(text) == stop and without_stop(text) == clause


# --- a real run --------------------------------------------------------------------------------------
def test_a_failed_run_holds_its_sentence_and_traceback_and_its_output_no_paths(tmp_path):
    lines: list[tuple[str, str]] = []
    results: list[RunResult] = []
    runner = ProgramRunner(limits=Limits(wall_seconds=60), on_output=lambda s, line: lines.append((s, line)),
                           on_exit=results.append)
    path = tmp_path / "no_open.py"
    path.write_text("from asibot.client import CartesianClient\nprint('before')\nrobot = CartesianClient()\n"
                    "robot.movl([0.1, 0.2, 0.3, 0, 0])\n")
    try:
        runner.start(path, "asibot-sim", name="no_open")
        wait_until(lambda: results, timeout=30, message="the program did not end")
    finally:
        runner.close()
    result = results[0]
    assert not result.ok and result.line == 4
    assert result.error == "Line 4: Call open(robot) first."
    assert result.reason == "failed with an error on line 4: Call open(robot) first"
    assert result.details[0] == "Traceback (most recent call last):"
    assert result.details[1:3] == ['  File "no_open.py", line 4, in <module>', "    robot.movl([0.1, 0.2, 0.3, 0, 0])"]
    assert result.details[3].startswith('  File "asibot.client", line ') and result.details[3].endswith(", in movl")
    assert result.details[-1] == "asibot.errors.RpcError: Call open(robot) first."
    # The output the page reloads has no traceback left (it is the details); what went by live
    # named no file by its path.
    assert runner.output() == [("out", "before")]
    errs = [line for stream, line in lines if stream == "err"]
    assert errs and not any(str(tmp_path) in e or os.sep + "asibot" + os.sep in e for e in errs), errs
    assert runner.status()["last"]["error"] == result.error
