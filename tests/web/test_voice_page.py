"""The page's microphone: a task launched by saying its word, with chromium's fake microphone
playing a phrase spoken by espeak-ng (the voice service hears it through the page, the web
server and the bus, as it would a person's voice), and a phrase it does not know launching
nothing."""

from __future__ import annotations

import contextlib
import json
import subprocess
import wave
from pathlib import Path

import numpy as np
import pytest

from asibot import keys
from asibot.messages import Event, VoiceHeard
from asibot.testing import Inbox, wait_until

from .conftest import CHROMIUM, CHROMIUM_ARGS, _stack, http, screenshot

pytestmark = [pytest.mark.slow, pytest.mark.alone, pytest.mark.timeout(300)]
ROBOT = "asibot-sim"
RED_CAN = Path(__file__).resolve().parents[2] / "libs" / "common" / "asibot" / "examples" / "give_me_the_red_can.py"


def spoken(folder: Path, text: str) -> Path:
    """`text` by espeak-ng between two seconds of silence (chromium plays the file in a loop):
    the voice activity detection sees one utterance a loop."""
    raw = folder / "raw.wav"
    subprocess.run(["espeak-ng", "-v", "en-us", "-s", "140", "-w", str(raw), text], check=True, capture_output=True)
    with wave.open(str(raw)) as w:
        rate, speech = w.getframerate(), np.frombuffer(w.readframes(w.getnframes()), np.int16)
    quiet = np.zeros(2 * rate, np.int16)
    out = folder / f"{text.replace(' ', '_')}.wav"
    with wave.open(str(out), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(rate)
        w.writeframes(np.concatenate([quiet, speech, quiet]).tobytes())
    return out


@pytest.fixture(scope="module")
def kitchen_voice(tmp_path_factory):
    stack = _stack(tmp_path_factory.mktemp("voice"), ["kinematics-asibot-sim", "voice"],
                   ["sim/asibot-sim", "kinematics/asibot-sim", "voice/asibot-sim"])
    try:    # a failed set-up must not leave the stack running under the rest of the suite
        http(stack, "PUT", "/api/programs/say_hello", {"text": "print('hello from a spoken task')\n"})
        http(stack, "PUT", "/api/programs/give_me_the_red_can", {"text": RED_CAN.read_text()})
        http(stack, "POST", "/api/words", {"text": "give me the red can"})
        http(stack, "PUT", "/api/tasks/Red%20can",
             {"program": "give_me_the_red_can", "words": ["give me the red can"], "icon": "can.svg"})
        # the voice service asks the Task Creator for the tasks' words every few seconds
        wait_until(lambda: "give me the red can" in json.dumps(stack.bus.call(keys.voice_rpc("status"), timeout=5)),
                   20, interval=0.5, message="the voice service never learnt the task's words")
        yield stack
    finally:
        stack.stop()


@contextlib.contextmanager
def listening(stack, folder: Path, phrase: str):
    """A browser whose microphone says `phrase` in a loop, listening on the Speech tab; yields
    the page and what the bus heard (VoiceHeard) and told (the robot's events) meanwhile."""
    from playwright.sync_api import sync_playwright
    heard, events = Inbox(), Inbox()
    subs = [stack.bus.subscribe(keys.voice_heard(), VoiceHeard, heard),
            stack.bus.subscribe(keys.events(ROBOT), Event, events)]
    wav = spoken(folder, phrase)
    errors: list[str] = []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=[
            *CHROMIUM_ARGS, "--use-fake-ui-for-media-stream", "--use-fake-device-for-media-stream",
            f"--use-file-for-fake-audio-capture={wav}", "--autoplay-policy=no-user-gesture-required"])
        try:
            page = browser.new_page(viewport={"width": 1366, "height": 900})
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(stack.web_url + "#speech")
            page.wait_for_selector("body[data-ready=true]")
            page.get_by_role("button", name="Listen to the microphone").click()
            page.get_by_text("Listening: say a task's word").wait_for(timeout=10000)
            yield page, heard, events
        finally:
            browser.close()
            for sub in subs:
                sub.close()
    assert not errors, errors


def can_position(stack) -> list[float]:
    return stack.bus.call(keys.driver_rpc(ROBOT, "object_pose"), {"name": "red_can"})["pos"]


def test_the_red_can_is_fetched_by_saying_give_me_the_red_can_into_the_page(kitchen_voice, tmp_path):
    """The issue's "done when", by voice: the seed's program, launched by its words, no mouse."""
    can = can_position(kitchen_voice)
    with listening(kitchen_voice, tmp_path, "give me the red can") as (page, heard, events):
        wait_until(lambda: any(h.action == "launch" for h in heard.all()), 60, interval=0.2,
                   message=f"heard: {[(h.action, h.text, h.reason) for h in heard.all()]}")
        launched = next(h for h in heard.all() if h.action == "launch")
        assert launched.task == "Red can" and launched.source.startswith("web-")
        wait_until(lambda: any(e.code == "task_done" and e.text == "Red can: done" for e in events.all()), 120,
                   message=f"the task did not end well: {[(e.code, e.text) for e in events.all()]}")
        lifted = can_position(kitchen_voice)
        assert lifted[2] > can[2] + 0.08, f"the can is at {lifted}, it was at {can}"
        page.get_by_text("“give me the red can”: started Red can.").first.wait_for(timeout=10000)
        screenshot(page, "speech-heard")
        page.get_by_role("button", name="Stop listening").click()
        page.get_by_text("Not listening.").wait_for(timeout=5000)


def test_a_phrase_it_does_not_know_launches_nothing(kitchen_voice, tmp_path):
    with listening(kitchen_voice, tmp_path, "what a lovely morning it is") as (page, heard, events):
        wait_until(lambda: len(heard.all()) >= 2, 60, interval=0.2, message="nothing was cut from the audio")
        assert all(h.action == "nothing" for h in heard.all()), [(h.action, h.text) for h in heard.all()]
        assert not any(e.code == "task_started" for e in events.all())
        page.locator(".events li", has_text="Something I do not know").first.wait_for(timeout=10000)


def test_asking_yes_first_is_set_on_the_page_and_a_task_heard_then_waits_for_yes(kitchen_voice, tmp_path):
    with listening(kitchen_voice, tmp_path, "give me the red can") as (page, heard, events):
        ask = page.get_by_role("button", name='Ask me "yes" first')
        ask.click()
        page.get_by_text('A task heard now starts after you say "yes".').wait_for(timeout=10000)
        assert ask.get_attribute("aria-pressed") == "true"
        assert http(kitchen_voice, "GET", "/api/voice") == {"confirm": True}
        start = len(heard.all())
        wait_until(lambda: any(h.action == "ask" for h in heard.all()[start:]), 60, interval=0.2,
                   message=f"heard: {[(h.action, h.text) for h in heard.all()[start:]]}")
        assert not any(h.action == "launch" for h in heard.all()[start:])
        page.get_by_text("“give me the red can”: asked about Red can.").first.wait_for(timeout=10000)
        screenshot(page, "speech-ask-first")
        page.get_by_role("button", name="Start a task at once").click()
        page.get_by_text("A task heard now starts at once.").wait_for(timeout=10000)
        assert http(kitchen_voice, "GET", "/api/voice") == {"confirm": False}


def test_a_made_up_word_is_recorded_by_saying_it_on_the_page_and_then_launches_its_task(kitchen_voice, tmp_path,
                                                                                      burners_paused):
    """'zorblat' is in no dictionary: the voice service cannot listen for it until the page's
    "Record by saying it" has learned how it is said from the microphone."""
    http(kitchen_voice, "POST", "/api/words", {"text": "zorblat"})
    http(kitchen_voice, "PUT", "/api/tasks/Zorblat", {"program": "say_hello", "words": ["zorblat"], "icon": "can.svg"})
    status = lambda: kitchen_voice.bus.call(keys.voice_rpc("status"), timeout=5)   # noqa: E731
    wait_until(lambda: "zorblat" in status()["refused"], 20, interval=0.5,
               message="the voice service never saw the task's word")
    with listening(kitchen_voice, tmp_path, "zorblat") as (page, heard, events):
        # chromium plays the word in a loop from its start: once one saying was heard whole, the
        # next one starts after the button is pressed, as a person's would
        wait_until(lambda: heard.all(), 30, interval=0.2, message="nothing was cut from the audio")
        row = page.locator(".points li", has_text="zorblat")
        row.get_by_role("button", name="Record by saying it: zorblat").click()
        row.get_by_text("Learned: ").wait_for(timeout=30000)
        assert "zorblat" in status()["words"]
        # the microphone keeps saying it: now it is heard, and launches the task
        launched = lambda: any(h.action == "launch" and h.task == "Zorblat" for h in heard.all())  # noqa: E731
        learned_at = len(heard.all())
        try:
            wait_until(launched, 40, interval=0.2)
            again = "matches."
        except AssertionError:
            # With both cores busy, chromium's fake microphone skips audio and the first saying
            # can be learned cut ("L ER OW G" for zorblat, twice under --cpu-burners 2): the
            # user's remedy is the page's own, saying it again, which must then work.
            first = (row.inner_text(), [(h.action, h.reason) for h in heard.all()[learned_at:]][:3])
            row.get_by_role("button", name="Say it again: zorblat").click()
            page.get_by_text("Heard it again:", exact=False).wait_for(timeout=30000)
            learned_at = len(heard.all())
            try:
                wait_until(launched, 60, interval=0.2)
            except AssertionError:
                raise AssertionError(f"the learned word never launched its task; first {first}; the row says "
                                     f"{row.inner_text()!r}; heard since: "
                                     f"{[(h.action, h.text, h.reason) for h in heard.all()[learned_at:]]}")
            again = ""
        row.get_by_role("button", name="Say it again: zorblat").click()
        page.get_by_text(f"Heard it again: {again}", exact=False).wait_for(timeout=30000)
        # the same saying heard twice is kept once: the row counts the different ones
        kept = http(kitchen_voice, "GET", "/api/voice/learned")["words"]["zorblat"]
        assert 1 <= len(kept) <= 3, kept
        row.get_by_text(f"({len(kept)} of 3 sayings)", exact=False).wait_for(timeout=10000)
        screenshot(page, "speech-learned")
        row.get_by_role("button", name="Forget how I say it: zorblat").click()
        row.get_by_role("button", name="Record by saying it: zorblat").wait_for(timeout=10000)
        wait_until(lambda: "zorblat" in status()["refused"], 10, message="the word was not forgotten")
        page.get_by_role("button", name="Stop listening").click()
