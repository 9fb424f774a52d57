"""The voice service on the in-memory bus: espeak-ng speech streamed as a browser streams its
microphone (100 ms chunks of 48 kHz float32 stereo) to a Task Creator double that serves
keys.tasks_rpc as the web service does; the words, the stop, the question, bad audio, sources
that go silent, floods, the local microphone, the service's shape."""

from __future__ import annotations

import json
import sys
import threading
import types

import numpy as np
import pytest

from asibot import keys, messages, runtime
from asibot.bus import Bus
from asibot.errors import RpcError
from asibot.messages import AudioChunk, EStop, Event, VoiceHeard
from asibot.testing import Inbox, wait_until
from asibot.voice import service
from asibot.voice.commands import Commands, Stopped, Transcript
from asibot.voice.recognizer import Heard
from asibot.voice.speaker import Speaker
from asibot.voice.streams import Streams

from .sounds import fft_resample, noise

ROBOT = "asibot-sim"
TASKS = {"Drink water": ["drink"], "Red can": ["Give me the red can!"]}
SOURCE = "web-page1"


class TaskDesk:
    """The web service's tasks verbs (services/web/asibot/web/tasks_bus.py): list, launch on a robot (one
    program at a time, events on the robot's key), stop; every call recorded."""

    def __init__(self, bus: Bus, tasks: dict[str, list[str]]) -> None:
        self.bus, self.tasks = bus, {k: list(v) for k, v in tasks.items()}
        self.running = ""
        self._lock = threading.Lock()
        self.calls: list[tuple[str, dict]] = []
        self._events = bus.publisher(keys.events(ROBOT), Event)
        for verb in ("list", "launch", "stop"):
            bus.serve(keys.tasks_rpc(verb), self._recorded(verb))

    def _recorded(self, verb):
        def handle(req: dict) -> dict:
            with self._lock:
                self.calls.append((verb, dict(req)))
            return getattr(self, "_" + verb)(req)
        return handle

    def verbs(self, verb: str) -> list[dict]:
        with self._lock:
            return [r for v, r in self.calls if v == verb]

    def _list(self, req: dict) -> dict:
        return {"tasks": [{"name": n, "program": n.lower().replace(" ", "_") + ".py", "words": list(w)}
                          for n, w in self.tasks.items()]}

    def _launch(self, req: dict) -> dict:
        if self.running:
            raise RpcError("busy", f"A program is already running ({self.running}); stop it first.")
        self.running = req["task"]
        self._events.put(Event(level="info", code="task_started", text=f"{req['task']}: started"))
        return {"task": req["task"], "program": "p.py", "robot": req["robot"]}

    def _stop(self, req: dict) -> dict:
        self.running = ""
        return {}

    def finish(self) -> None:
        task, self.running = self.running, ""
        self._events.put(Event(level="info", code="task_done", text=f"{task}: done"))


class Rig:
    """The service, the double, live drivers, and a test bus with what the service publishes."""

    def __init__(self, speech, *argv: str, tasks=TASKS, drivers=(ROBOT,)) -> None:
        self.speech = speech
        self.closed = False
        self.web_bus, self.test_bus, self.voice_bus = Bus("web"), Bus("test"), Bus("voice")
        self.desk = TaskDesk(self.web_bus, tasks)
        for robot in drivers:
            self.test_bus.announce(keys.driver_alive(robot))
        self.heard, self.events, self.local, self.estops = Inbox(), Inbox(), Inbox(), Inbox()
        self.test_bus.subscribe(keys.voice_heard(), VoiceHeard, self.heard)
        self.test_bus.subscribe(keys.voice_events(SOURCE), Event, self.events)
        self.test_bus.subscribe(keys.voice_events("local"), Event, self.local)
        self.test_bus.subscribe(keys.every_robot(keys.estop), EStop, lambda k, m: self.estops((k, m)), with_key=True)
        self.mic = self.test_bus.publisher(keys.voice_audio(SOURCE), AudioChunk)
        args = runtime.parser(service.NAME, service.add_arguments).parse_args(["--quiet", "--refresh", "0.2", *argv])
        self.svc = service.build(self.voice_bus, args)
        wait_until(lambda: self.svc.words(), message="the service never learnt the tasks' words")

    def say(self, text: str, part: float = 1.0, tail: float = 1.0, voice: tuple[str, int] = ("en-us", 140)) -> None:
        """Stream `text` (its first `part`) between quiet, as a browser: 100 ms chunks."""
        for chunk in browser_chunks(self.speech, text, part, tail, voice=voice):
            self.put(chunk)

    def put(self, data: np.ndarray | bytes, rate: int = 48000, sample: str = "float32", channels: int = 2) -> None:
        raw = data.tobytes() if isinstance(data, np.ndarray) else data
        self.mic.put(AudioChunk(data=raw, rate=rate, sample=sample, channels=channels))

    def next_heard(self, count: int) -> VoiceHeard:
        """The `count`-th VoiceHeard (1-based), waited for."""
        wait_until(lambda: len(self.heard) >= count, 15, message=f"utterance {count} was never heard: "
                                                                 f"{self.heard.all()}")
        return self.heard.all()[count - 1]

    @property
    def said(self) -> list[str]:
        return self.svc.speaker.said

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        self.svc.close()
        for bus in (self.voice_bus, self.test_bus, self.web_bus):
            bus.close()


def browser_chunks(speech, text: str, part: float = 1.0, tail: float = 1.0, rate: int = 48000,
                   voice: tuple[str, int] = ("en-us", 140)):
    x, r = speech.samples(text, *voice)
    phrase = fft_resample(x[: int(len(x) * part)] / 32768.0, r, rate)
    mono = np.concatenate([noise(0.5, -60, rate, seed=1), phrase, noise(tail, -60, rate, seed=2)])
    stereo = np.stack([mono, 0.7 * mono], axis=1).astype(np.float32)
    n = rate // 10
    return [stereo[i:i + n] for i in range(0, len(stereo), n)]


@pytest.fixture
def rig(memory_bus, speech):
    made = []

    def make(*argv, **kw) -> Rig:
        made.append(Rig(speech, *argv, **kw))
        return made[-1]

    yield make
    for r in made:
        r.close()


def test_a_spoken_task_word_launches_that_task_and_says_how_it_went(rig):
    r = rig()
    r.say("drink")
    h = r.next_heard(1)
    assert (h.source, h.text, h.word, h.action, h.task) == (SOURCE, "drink", "drink", "launch", "Drink water")
    assert 0 < h.confidence <= 1 and h.said == "Starting Drink water."
    assert r.desk.verbs("launch") == [{"task": "Drink water", "robot": ROBOT}]
    r.say("give me the red can")             # one program at a time: the Task Creator says no
    h = r.next_heard(2)
    assert (h.word, h.action, h.task) == ("Give me the red can!", "refused", "Red can")
    assert h.reason == "A program is already running (Drink water); stop it first."
    assert h.said == "I cannot start Red can. A program is already running (Drink water); stop it first."
    r.desk.finish()
    wait_until(lambda: "Drink water: done." in r.said)
    assert r.said == ["Starting Drink water.", h.said, "Drink water: done."]
    assert r.estops.all() == []


def test_other_speech_launches_nothing(rig):
    r = rig()
    r.say("what is the weather like today")
    h = r.next_heard(1)
    assert (h.action, h.text, h.word, h.task, h.said) == ("nothing", "", "", "", "")
    assert h.reason.endswith(".") and h.reason[0].isupper()
    assert r.desk.verbs("launch") == [] and r.said == [] and r.estops.all() == []


def test_stop_engages_the_estop_of_every_live_robot_and_stops_the_task(rig):
    r = rig(drivers=(ROBOT, "pioneer-sim"))
    r.say("drink")
    assert r.next_heard(1).action == "launch" and r.desk.running == "Drink water"
    r.say("stop stop")
    h = r.next_heard(2)
    assert (h.text, h.action) == ("stop", "stop")
    wait_until(lambda: len(r.estops) == 2)
    assert sorted(k for k, _ in r.estops.all()) == [keys.estop("asibot-sim"), keys.estop("pioneer-sim")]
    assert all(m.engaged and "(voice, pid" in m.by for _, m in r.estops.all())
    assert r.desk.verbs("stop") == [{}] and r.desk.running == ""
    assert h.said == "Stopped. Release the emergency stop on the screen to go on."
    assert len(r.desk.verbs("launch")) == 1


def test_confirm_yes_launches_no_and_silence_do_not(rig):
    r = rig("--confirm", "--answer-seconds", "1")
    r.say("drink")
    h = r.next_heard(1)
    assert (h.action, h.task, h.said) == ("ask", "Drink water", "Shall I start Drink water? Say yes or no.")
    r.say("no")
    h = r.next_heard(2)
    assert (h.text, h.action, h.said) == ("no", "cancel", "Cancelled.")
    r.say("drink")
    assert r.next_heard(3).action == "ask"
    r.say("yes")
    h = r.next_heard(4)
    assert (h.text, h.action, h.task) == ("yes", "launch", "Drink water")
    assert r.desk.verbs("launch") == [{"task": "Drink water", "robot": ROBOT}]
    r.desk.finish()
    r.say("drink")
    assert r.next_heard(5).action == "ask"
    h = r.next_heard(6)                                      # nobody answers within 1 s
    assert (h.source, h.action, h.task, h.reason) == (SOURCE, "cancel", "Drink water", "No answer within 1 s.")
    assert len(r.desk.verbs("launch")) == 1


def test_the_pages_ask_yes_first_setting_is_kept_and_bad_values_change_nothing(rig, tmp_path, monkeypatch):
    monkeypatch.setenv("ASIBOT_DATA", str(tmp_path))
    r = rig()
    call = lambda req: r.test_bus.call(keys.voice_rpc("settings"), req, timeout=5)["confirm"]   # noqa: E731
    assert call({}) is False
    with pytest.raises(RpcError) as exc:
        call({"confirm": "yes"})
    assert exc.value.code == "bad_request" and "true or false" in exc.value.message
    assert call({"confirm": True}) is True
    r.say("drink")
    assert r.next_heard(1).action == "ask"
    assert json.loads((tmp_path / "voice" / "settings.json").read_text()) == {"confirm": True}
    r.close()
    again = rig()                                             # a restart keeps the person's choice
    assert again.test_bus.call(keys.voice_rpc("status"), timeout=5)["confirm"] is True


def test_a_word_added_to_a_task_is_heard_after_the_refresh(rig):
    r = rig()
    r.say("open the fridge")
    assert r.next_heard(1).action == "nothing"
    r.desk.tasks["Fridge"] = ["Open the fridge."]
    wait_until(lambda: "Open the fridge." in r.svc.words(), message="the new word never reached the grammar")
    r.say("open the fridge")
    h = r.next_heard(2)
    assert (h.word, h.action, h.task) == ("Open the fridge.", "launch", "Fridge")


def test_without_the_task_creator_the_last_words_are_kept_and_health_says_so(rig):
    r = rig()
    assert r.svc.health()["tasks"] == "ok"
    r.web_bus.close()
    wait_until(lambda: r.svc.health()["tasks"] != "ok")
    assert "Keeping the 2 words heard before." in r.svc.health()["tasks"]
    r.say("drink")
    h = r.next_heard(1)
    assert (h.action, h.task) == ("refused", "Drink water")
    assert h.said == "I cannot start Drink water. The Task Creator is not running, so no task can start."


def bad_chunks(good: np.ndarray) -> list[tuple[str, bytes, dict]]:
    """(what the sentence says, payload, fields) of chunks a broken client or device sends."""
    nan = good.copy()
    nan[10, 0] = np.nan
    fields = dict(rate=48000, sample="float32", channels=2)

    def chunk(data, **kw):
        return messages.encode(AudioChunk(data=data, **{**fields, **kw}))

    return [
        ("contains NaN or infinity", chunk(nan.tobytes()), fields),
        ("96000 Hz is not supported", chunk(good.tobytes(), rate=96000), fields),
        ("is empty", chunk(b""), fields),
        ("not a whole number of 8-byte frames", chunk(good.tobytes()[:-3]), fields),
        ("sample type 'float64' is not supported", chunk(good.tobytes(), sample="float64"), fields),
        ("3 channels is not supported", chunk(good.tobytes(), channels=3), fields),
        ("send at most 1 s at a time", chunk(np.zeros((96000, 2), np.float32).tobytes()), fields),
        ("is 48000 Hz float32 stereo, but a chunk said 16000 Hz int16 mono",
         chunk(np.zeros(1600, np.int16).tobytes(), rate=16000, sample="int16", channels=1), fields),
        ("invalid AudioChunk.rate: expected an integer", messages.pack({**fields, "data": b"", "rate": "48000"}),
         fields),
    ]


def test_bad_chunks_get_a_sentence_and_change_nothing(rig, speech):
    r = rig()
    chunks = browser_chunks(speech, "drink")
    half = len(chunks) // 2
    for c in chunks[:half]:
        r.put(c)
    bad = bad_chunks(chunks[half])
    for _, payload, _ in bad:                                  # in the middle of the word
        r.test_bus.put_raw(keys.voice_audio(SOURCE), payload)
    for c in chunks[half:]:
        r.put(c)
    h = r.next_heard(1)
    assert (h.action, h.task) == ("launch", "Drink water")     # the word, whole: nothing of the bad chunks kept
    wait_until(lambda: len(r.events) >= len(bad))
    for (words, _, _), event in zip(bad, r.events.all()):
        assert event.code in ("bad_audio", "format_changed") and event.level == "warning"
        assert words in event.text and event.text[0].isupper() and event.text.endswith("."), event.text
    assert len(r.heard) == 1 and len(r.desk.verbs("launch")) == 1 and r.estops.all() == []


def test_a_silent_source_is_forgotten_with_its_unfinished_phrase(rig):
    r = rig("--source-timeout", "0.5")
    r.say("give me the red can", part=0.6, tail=0.0)           # the tab closes mid-phrase
    wait_until(lambda: len(r.events) >= 1, message="the source was never forgotten")
    event = r.events.last()
    assert (event.code, event.level) == ("source_forgotten", "info")
    assert event.text == f"No audio from {SOURCE!r} for 0.5 s: it is forgotten and its unfinished phrase dropped."
    assert r.svc.streams.sources() == {}
    assert len(r.heard) == 0 and r.desk.verbs("launch") == []


def test_a_flood_of_audio_is_dropped_within_bounds(shared_recognizer, speech):
    """Audio that arrives faster than it is heard: at most max_queued s wait, the rest is dropped
    with a sentence, told once until the source catches up."""
    gate, notices, results = threading.Event(), Inbox(), Inbox()

    def held(source, result):
        results((source, result))
        gate.wait(10)                                        # the worker is busy: nothing is heard meanwhile

    streams = Streams(shared_recognizer, held, lambda *n: notices(n), max_queued=3.0)
    try:
        for c in browser_chunks(speech, "drink"):
            streams.put("web-a", c.tobytes(), 48000, "float32", 2)
        wait_until(lambda: len(results) == 1)
        quiet = np.zeros((4800, 2), np.float32).tobytes()
        accepted = [streams.put("web-a", quiet, 48000, "float32", 2) for _ in range(50)]
        assert accepted[:20] == [True] * 20 and not all(accepted)
        assert streams.queued() <= 3.0
        assert [n[2] for n in notices.all()] == ["audio_overflow"]         # once, however many dropped
        assert "arrives faster than it can be heard" in notices.last()[3]
    finally:
        gate.set()
        streams.close()


class FakeInputStream:
    """sounddevice.InputStream playing `BLOCKS` to its callback, then going silent (a stuck device)."""

    BLOCKS: list[np.ndarray] = []

    def __init__(self, device, samplerate, channels, dtype, blocksize, callback) -> None:
        assert (samplerate, channels, dtype) == (44100, 1, "float32")
        self.callback, self.thread = callback, threading.Thread(target=self._play, daemon=True)

    def start(self) -> None:
        self.thread.start()

    def _play(self) -> None:
        for block in self.BLOCKS:
            self.callback(block.reshape(-1, 1), len(block), None, None)

    def stop(self) -> None:
        self.thread.join(5)

    def close(self) -> None:
        pass


def test_the_local_microphone_is_heard_and_a_device_that_sends_nan_then_stops_moves_nothing(rig, speech,
                                                                                          monkeypatch):
    x, rate = speech.samples("drink")
    mono = np.concatenate([noise(0.5, -60, 44100, 1), fft_resample(x / 32768.0, rate, 44100),
                           noise(1.0, -60, 44100, 2)]).astype(np.float32)
    blocks = [mono[i:i + 4410] for i in range(0, len(mono) - 4410, 4410)]
    FakeInputStream.BLOCKS = blocks + [np.full(4410, np.nan, np.float32)]
    fake = types.SimpleNamespace(InputStream=FakeInputStream,
                                 query_devices=lambda device, kind: {"name": "fake mic", "default_samplerate": 44100.0})
    monkeypatch.setitem(sys.modules, "sounddevice", fake)
    r = rig("--local-mic", "--source-timeout", "0.5")
    h = r.next_heard(1)
    assert (h.source, h.action, h.task) == ("local", "launch", "Drink water")
    wait_until(lambda: [e.code for e in r.local.all()] == ["bad_audio", "source_forgotten"])
    assert "NaN or infinity" in r.local.all()[0].text
    assert r.svc.health()["mic"] == "fake mic" and len(r.desk.verbs("launch")) == 1


def test_build_refuses_bad_arguments_with_a_sentence(memory_bus, monkeypatch):
    bus = Bus("voice")
    try:
        for argv, words in ((["--robot", "a/b"], "--robot: robot id 'a/b' is not a valid name"),
                            (["--answer-seconds", "0"], "--answer-seconds must be between 1 and 60 s, not 0"),
                            (["--refresh", "0"], "--refresh must be between"),
                            (["--source-timeout", "100"], "--source-timeout must be between 0.2 and 60 s"),
                            (["--speed", "20"], "--voice / --speed: The speed must be 80 to 450")):
            args = runtime.parser(service.NAME, service.add_arguments).parse_args(argv)
            with pytest.raises(ValueError, match=words):
                service.build(bus, args)
        monkeypatch.setitem(sys.modules, "sounddevice", None)          # not installed
        args = runtime.parser(service.NAME, service.add_arguments).parse_args(["--local-mic", "--quiet"])
        with pytest.raises(ValueError, match="--local-mic needs sounddevice and the PortAudio library"):
            service.build(bus, args)
    finally:
        bus.close()


class Robots:
    def __init__(self) -> None:
        self.launched: list[str] = []
        self.stops = 0
        self.while_launching = lambda: None

    def launch(self, task: str) -> None:
        self.while_launching()
        self.launched.append(task)

    def stop(self) -> Stopped:
        self.stops += 1
        return Stopped(("asibot-sim",))


def heard(word: str) -> Heard:
    return Heard(word.lower(), word, 0.9, -3.0, 1.0, 0.8)


def test_a_stop_voids_what_was_heard_before_it_and_the_question():
    robots = Robots()
    commands = Commands(robots, Transcript(), confirm=True)
    commands.set_tasks([{"name": "Drink water", "words": ["drink"]}, {"name": "bad"}, "junk"])
    ticket = commands.ticket()
    assert commands.hear(heard("drink"), ticket=ticket).action == "ask"
    assert commands.hear(heard("stop")).action == "stop" and robots.stops == 1
    assert commands.pending == ""
    assert commands.hear(heard("yes")).action == "nothing"                 # the question went with the stop
    assert commands.hear(heard("drink"), ticket=ticket).action == "cancel"  # heard before the stop
    assert robots.launched == []


def test_a_stop_heard_while_a_task_starts_stops_it_too():
    robots = Robots()
    commands = Commands(robots, Transcript())
    commands.set_tasks([{"name": "Drink water", "words": ["drink"]}])
    robots.while_launching = lambda: commands.hear(heard("stop"))
    outcome = commands.hear(heard("drink"))
    assert (outcome.action, outcome.said) == ("cancel", "") and robots.stops == 2
    assert commands.speaker.said == ["Stopped. Release the emergency stop on the screen to go on."]


def test_a_speaker_that_cannot_speak_breaks_nothing():
    robots = Robots()
    commands = Commands(robots, Speaker(program="espeak-ng-not-installed"))
    commands.set_tasks([{"name": "Drink water", "words": ["drink"]}])
    outcome = commands.hear(heard("drink"))
    assert (outcome.action, outcome.said) == ("launch", "Starting Drink water.") and robots.launched == ["Drink water"]


def test_a_task_creator_that_starts_after_the_voice_is_waited_for_without_a_warning(memory_bus, caplog):
    """`asibot up` starts the web and the voice together: until the web answers, the voice waits
    (health says so) and warns nobody; once it answers, its words are heard."""
    voice_bus, web_bus = Bus("voice"), Bus("web")
    args = runtime.parser(service.NAME, service.add_arguments).parse_args(["--quiet", "--refresh", "0.2"])
    svc = service.build(voice_bus, args)
    try:
        wait_until(lambda: svc.health()["tasks"] == service.WAITING_FOR_TASKS)
        desk = TaskDesk(web_bus, TASKS)
        wait_until(lambda: "drink" in svc.words(), message="the words never came once the Task Creator answered")
        assert svc.health()["tasks"] == "ok" and desk.verbs("list")
        assert not [r for r in caplog.records if r.levelname == "WARNING" and "cannot update the words" in r.message]
    finally:
        svc.close()
        voice_bus.close()
        web_bus.close()
