"""The typed clients check what a service answers: a reply of another shape raises RpcError with
a sentence, never a KeyError from inside the client."""

from __future__ import annotations

import pytest

from asibot import keys
from asibot.bus import Bus
from asibot.client import TasksClient, VoiceClient
from asibot.errors import RpcError, Unavailable


@pytest.mark.parametrize("reply", [{}, {"tasks": "Give me the red can"}, {"tasks": None}])
def test_a_task_list_of_another_shape_is_an_rpc_error(memory_bus, reply):
    bus = Bus("web")
    bus.serve(keys.tasks_rpc("list"), lambda req: reply)
    with pytest.raises(RpcError) as err:
        TasksClient.on(bus, "asibot-sim", timeout=2.0).tasks()
    assert err.value.code == "internal"
    assert "no list of tasks" in err.value.message
    bus.close()


def test_a_list_of_tasks_is_returned_as_served(memory_bus):
    bus = Bus("web")
    tasks = [{"name": "Give me the red can", "program": "red_can.py", "words": ["red can"]}]
    bus.serve(keys.tasks_rpc("list"), lambda req: {"tasks": tasks})
    assert TasksClient.on(bus, "asibot-sim", timeout=2.0).tasks() == tasks
    bus.close()


class VoiceDouble:
    """Serves keys.voice_rpc as the voice service does, keeping what each verb was asked."""

    def __init__(self, bus: Bus) -> None:
        self.asked: list[tuple[str, dict]] = []
        self.confirm = False
        for verb in ("status", "settings", "learn", "forget", "learned"):
            bus.serve(keys.voice_rpc(verb), self._answer(verb))

    def _answer(self, verb: str):
        def answer(req: dict) -> dict:
            self.asked.append((verb, req))
            if verb == "settings" and "confirm" in req:
                self.confirm = req["confirm"]
            if verb == "learn" and req.get("source") == "web-silent":
                raise RpcError("timeout", "Nothing was said into 'web-silent' within 1 s. Nothing was learned.")
            return {"settings": {"confirm": self.confirm}, "status": {"words": ["give me the red can"]},
                    "learn": {"phrase": req.get("word"), "phones": "g ih v"},
                    "forget": {"phrase": req.get("word"), "forgotten": 2},
                    "learned": {"words": {}, "phrases": {w: w.lower() for w in req.get("words", [])}}}[verb]
        return answer


def test_the_voice_client_asks_each_verb_and_answers_without_the_ok(memory_bus):
    bus = Bus("web")
    voice_bus = Bus("voice")
    double = VoiceDouble(voice_bus)
    voice = VoiceClient.on(bus, timeout=2.0)
    assert voice.settings() is False and double.asked[-1] == ("settings", {})
    assert voice.settings(True) is True and double.asked[-1] == ("settings", {"confirm": True})
    assert voice.learn("Give me the red can", source="web-1", seconds=2) == {"phrase": "Give me the red can", "phones": "g ih v"}
    assert double.asked[-1] == ("learn", {"word": "Give me the red can", "source": "web-1", "seconds": 2})
    assert voice.forget("red can") == {"phrase": "red can", "forgotten": 2}
    assert voice.learned(["Red Can"]) == {"words": {}, "phrases": {"Red Can": "red can"}}
    with pytest.raises(RpcError, match="Nothing was said") as err:
        voice.learn("red can", source="web-silent", seconds=1)
    assert err.value.code == "timeout"
    voice.close()                       # a borrowed bus stays open
    assert bus.call(keys.voice_rpc("status"), timeout=2.0)["words"] == ["give me the red can"]
    for b in (bus, voice_bus):
        b.close()


def test_a_voice_client_with_no_voice_service_says_how_to_start_it(memory_bus):
    with pytest.raises(Unavailable):
        VoiceClient.on(Bus("web"), timeout=0.5).status()
    with pytest.raises(RpcError, match=r"No voice service answers; start it with `python -m asibot.voice`") as err:
        VoiceClient(timeout=0.5).status()
    assert err.value.code == "unavailable"
