"""Voice recognition figures, each beside a reference measured in the same run.

Prints one markdown table, then the recognition rates. Inputs are espeak-ng speech made at
the start (5 voices x 3 speeds; the 4 phrases of the tests, stop, yes, no, and 15 phrases
that are not in the grammar). References: the utterance's own duration (so p50 / duration
is the real-time factor), pocketsphinx's decode alone (what our three rejection checks add
to it), numpy's FFT resampling of the same audio (the floor of any whole-buffer resampler;
ours streams), and the bare float32 -> mono decode.

The service rows run `asibot.voice.service` on the in-memory bus (no router) with a Task
Creator double: each utterance of the corpus is streamed as a browser streams it (100 ms chunks
of 48 kHz float32 stereo), all but the quiet that ends it; the clock starts when the chunk of
quiet that ends it is published and stops when the launch request (or the latched estop, for
"stop") arrives. Beside it: recognising the same utterances alone, and the VAD's hangover
(the quiet a speaker must leave before an utterance ends, which comes on top).

The learning rows teach made-up words (not in the dictionary) from one saying each, as the page's
"Record a word" does (`Learner.learn_recording`: three phone-loop readings in child processes,
the best one kept), then ask whether the word is heard in its other sayings (other voices and
speeds) and whether speech that is not it is still refused. Beside them: one reading in this
process (the phone loop alone), the choice between the readings, and the saying's duration.

Run: `.venv/bin/python bench/bench_voice.py [--quick]`
"""

from __future__ import annotations

import itertools
import os
import shutil
import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from asibot import keys
from asibot.bus import Bus
from asibot.messages import AudioChunk, EStop
from asibot.voice import service
from asibot.voice.audio import AudioFormat, Converter, decode, read_wav
from asibot.voice import phones
from asibot.voice.grammar import Lexicon, build_grammar
from asibot.voice.learning import Learner, speech_in
from asibot.voice.pronunciations import Pronunciations
from asibot.voice.recognizer import Listener, Recognizer
from asibot.voice.speaker import Speaker
from asibot.voice.vad import Vad, VadConfig

from table import QUICK_HELP, print_table, times  # bench/table.py: run as `python bench/<name>.py`

ASSIGNED = ["give me the red can", "open the fridge", "go to the desk", "drink"]
IN_GRAMMAR = ASSIGNED + ["stop", "yes", "no"]
OUT_OF_GRAMMAR = ["what is the weather like today", "turn on the television please", "hello robot",
                  "open the window", "give me the blue cup", "drink some water", "bring me a towel",
                  "where are my glasses", "call my daughter", "the cat is sleeping", "good morning",
                  "I am hungry", "close the door", "red", "can you hear me"]
VOICES = ["en-us", "en-us+m1", "en-us+f3", "en-us+m3", "en"]
SPEEDS = [120, 150, 180]
#: Words espeak-ng says and CMUdict lacks, so only learning can make them heard.
MADE_UP = ["zorblat", "quentifar", "mibbledoo"]
#: The saying each word is learned from; every other saying of VOICES x SPEEDS is a new one.
TEACHERS = [("en-us", 150), ("en-us+f3", 120), ("en", 180)]
ROWS: list[tuple[str, str, str, str, str]] = []
LEARNING_MISSES: list[str] = []
QUICK = False


def reps(n: int) -> int:
    """`n` timed calls, or two in a smoke run (--quick)."""
    return 2 if QUICK else n


def row(what: str, t: np.ndarray, unit: str = "ms", ref: str = "", scale: float = 1e3) -> None:
    ROWS.append((what, f"{np.percentile(t, 50) * scale:.2f}", f"{np.percentile(t, 99) * scale:.2f}", unit, ref))


def speak(folder: Path, text: str, voice: str, speed: int) -> np.ndarray:
    path = folder / "x.wav"
    subprocess.run(["espeak-ng", "-v", voice, "-s", str(speed), "-w", str(path), text], check=True)
    return read_wav(path)


_HISS = np.random.default_rng(2)


def microphone(x: np.ndarray) -> np.ndarray:
    """`x` as a microphone hears it: 0.3 s of quiet each side, and its hiss (-60 dBFS) over all.
    espeak-ng's digital silence is no microphone's: it hid false accepts (0 of 225 other phrases
    accepted without hiss, 10 with), and a word learned with hiss and listened for in clean
    speech was heard in 16 of 36 new sayings, with hiss on both in 35 to 36."""
    y = np.concatenate([np.zeros(4800), x, np.zeros(4800)]) + _HISS.standard_normal(len(x) + 9600) * 30
    return np.clip(y, -32768, 32767).astype(np.int16)


def main() -> None:
    global QUICK, VOICES, SPEEDS, OUT_OF_GRAMMAR, MADE_UP, TEACHERS
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help=QUICK_HELP)
    QUICK = ap.parse_args().quick
    if QUICK:
        VOICES, SPEEDS, OUT_OF_GRAMMAR = VOICES[:1], SPEEDS[1:2], OUT_OF_GRAMMAR[:2]
        MADE_UP, TEACHERS = MADE_UP[:1], TEACHERS[:1]
    if shutil.which("espeak-ng") is None:
        raise SystemExit("bench_voice needs espeak-ng: sudo apt-get install espeak-ng")
    folder = Path(tempfile.mkdtemp())
    corpus = [(text, text in IN_GRAMMAR, voice, speed, speak(folder, text, voice, speed))
              for voice, speed in itertools.product(VOICES, SPEEDS) for text in IN_GRAMMAR + OUT_OF_GRAMMAR]
    shutil.rmtree(folder)
    recognizer = Recognizer(build_grammar(ASSIGNED))

    # recognition, per utterance (every clip of the corpus, so p99 is over 330 utterances)
    decodes, seconds, verdicts = [], [], []
    for text, inside, voice, speed, x in corpus:
        d = recognizer.decode(x)
        decodes.append(d.decode_seconds)
        seconds.append(len(x) / 16000)
        verdicts.append((text, inside, voice, speed, d))
    decodes, seconds = np.array(decodes), np.array(seconds)
    hissed = [(text, inside, voice, speed, recognizer.decode(microphone(x))) for text, inside, voice, speed, x in corpus]
    row("recognise one utterance (pocketsphinx + the 3 checks), 7 phrases", decodes, ref="")
    d = recognizer._decoder
    bare = []
    for *_, x in corpus[:60]:
        t0 = time.perf_counter()
        d.start_utt()
        d.process_raw(x.tobytes(), full_utt=True)
        d.end_utt()
        bare.append(time.perf_counter() - t0)
    row("  reference: pocketsphinx decode alone (60 utterances)", np.array(bare))
    row("  reference: the utterance's duration", seconds)
    rtf = decodes / seconds
    ROWS.append(("  real-time factor (recognise / duration)", f"{np.percentile(rtf, 50):.3f}",
                 f"{np.percentile(rtf, 99):.3f}", "", "< 1: faster than speech"))
    big = Recognizer(build_grammar([f"{a} the {b} {c}" for a in ("give me", "bring me", "open", "close")
                                    for b in ("red", "blue", "green", "small", "big")
                                    for c in ("can", "cup", "box", "door", "bottle")]))
    row("recognise one utterance, 103 phrases", times(lambda: big.decode(corpus[1][4]), reps(30)))

    # audio in: one second of browser audio (48 kHz stereo float32) to 16 kHz
    rng = np.random.default_rng(0)
    second = (rng.standard_normal((48000, 2)) * 0.05).astype(np.float32)
    fmt = AudioFormat(48000, "float32", 2)
    conv = Converter(fmt)
    chunks = [second[i:i + 960] for i in range(0, 48000, 960)]          # 20 ms chunks
    row("1 s of 48 kHz stereo float32 -> 16 kHz, in 20 ms chunks", times(lambda: [conv.convert(c) for c in chunks], reps(30)),
        "ms per s")
    row("  same, one 1 s chunk", times(lambda: conv.convert(second), reps(30)), "ms per s")
    mono = second.mean(axis=1)
    row("  reference: numpy FFT resample of the 1 s (whole buffer)",
        times(lambda: np.fft.irfft(np.fft.rfft(mono)[:8001], 16000), reps(30)), "ms per s")
    row("  reference: float32 stereo -> mono check only", times(lambda: decode(second, fmt), reps(30)), "ms per s")
    conv44 = Converter(AudioFormat(44100, "float32", 2))
    second44 = second[:44100]
    row("1 s of 44.1 kHz stereo float32 -> 16 kHz (160/441 polyphase)", times(lambda: conv44.convert(second44), reps(30)),
        "ms per s")

    # VAD and the whole listener on a quiet stream (the common case: nobody speaks)
    quiet = (rng.standard_normal(16000) * 30).astype(np.int16)
    vad = Vad()
    row("VAD, 1 s of 16 kHz audio in 20 ms chunks", times(lambda: [vad.feed(quiet[i:i + 320])
                                                               for i in range(0, 16000, 320)], reps(30)), "ms per s")
    listener = Listener(recognizer, fmt)
    quiet48 = (rng.standard_normal((48000, 2)) * 0.001).astype(np.float32)
    chunks48 = [quiet48[i:i + 960] for i in range(0, 48000, 960)]
    row("Listener (resample + VAD), 1 s of quiet 48 kHz stereo in 20 ms chunks",
        times(lambda: [listener.feed(c) for c in chunks48], reps(30)), "ms per s", "budget 1000 (real time)")

    # grammar changes
    lex = Lexicon()
    for n in (4, 50, 200):
        words = [f"{a} {b} {c}" for a in ("give", "bring", "open", "close", "find") for b in ("me", "the", "a", "my")
                 for c in ("can", "cup", "box", "door", "bottle", "book", "phone", "pen", "glass", "plate")][:n]
        row(f"rebuild: build_grammar + set_grammar, {n} phrases", _rebuild_times(recognizer, words, lex))
    recognizer.set_grammar(build_grammar(ASSIGNED, lex))

    service_rows([(text, x) for text, inside, _, _, x in corpus if inside and text not in ("yes", "no")])
    learning_rows([(text, x) for text, inside, *_, x in corpus if not inside][:len(OUT_OF_GRAMMAR)])

    speaker = Speaker()
    row("speaker: synthesize 'Sorry, I did not understand.'",
        times(lambda: speaker.synthesize("Sorry, I did not understand."), reps(10)))
    mute = Speaker(player=[sys.executable, "-c", "import sys; sys.stdin.buffer.read()"])
    row("speaker: say() returns (speech goes on in the background)",
        times(lambda: mute.say("I will give you the red can."), reps(10)))
    mute.wait(10)

    print(f"voice benchmark: {len(corpus)} espeak-ng utterances ({len(VOICES)} voices x {len(SPEEDS)} speeds), "
          f"{seconds.mean():.2f} s on average; {os.cpu_count()} cores\n")
    print_table(ROWS, header=("what", "p50", "p99", "unit", "reference / budget"))
    print("\nThe corpus as espeak-ng says it (digital silence around):\n")
    print_rates(verdicts)
    print("\nThe same, as a microphone hears it (0.3 s of quiet each side, hiss at -60 dBFS over all):\n")
    print_rates(hissed)
    print(f"\nlearned words, after {len(TEACHERS)} sayings: not heard, or heard in other speech "
          f"({len(LEARNING_MISSES)}):")
    for miss in LEARNING_MISSES:
        print("  ", miss)


def service_rows(clips: list[tuple[str, np.ndarray]]) -> None:
    """Utterance end -> launch request (or estop) on the bus, through the whole service."""
    bus = Bus("bench", "mem://bench-voice")
    launched: list[float] = []
    estopped: list[float] = []
    bus.serve(keys.tasks_rpc("list"), lambda req: {"tasks": [{"name": w, "program": "p.py", "words": [w]}
                                                             for w in ASSIGNED]})
    bus.serve(keys.tasks_rpc("launch"), lambda req: launched.append(time.perf_counter()) or
              {"task": req["task"], "program": "p.py", "robot": req["robot"]})
    bus.serve(keys.tasks_rpc("stop"), lambda req: {})
    bus.announce(keys.driver_alive("asibot-sim"))
    bus.subscribe(keys.estop("asibot-sim"), EStop, lambda m: estopped.append(time.perf_counter()))
    args = argparse.Namespace(robot="asibot-sim", confirm=False, answer_seconds=8.0, refresh=2.0, source_timeout=2.0,
                              quiet=True, voice="en-us", speed=150, local_mic=False, mic_device=None)
    svc = service.build(Bus("voice", "mem://bench-voice"), args)
    deadline = time.monotonic() + 10.0
    while not svc.words():
        if time.monotonic() > deadline:
            raise SystemExit("bench_voice: the voice service never learnt the tasks' words")
        time.sleep(0.01)
    mic = bus.publisher(keys.voice_audio("web-bench"), AudioChunk)
    rng = np.random.default_rng(1)
    ending = VadConfig().hangover + 0.15                     # s of quiet that ends an utterance, and a margin

    def send(x16: np.ndarray) -> None:
        t48 = np.arange(len(x16) * 3) / 3.0
        x = np.interp(t48, np.arange(len(x16)), x16.astype(np.float32) / 32768.0)
        stereo = np.stack([x, x], 1).astype(np.float32)
        for i in range(0, len(stereo), 4800):
            mic.put(AudioChunk(data=stereo[i:i + 4800].tobytes(), rate=48000, sample="float32", channels=2))

    def quiet(seconds: float) -> np.ndarray:
        return (rng.standard_normal(int(seconds * 16000)) * 30).astype(np.int16)

    to_launch, to_stop, alone, missed = [], [], [], 0
    for text, x in clips:
        loud = np.flatnonzero(np.abs(x) > 300)
        x = x[: loud[-1] + 1] if len(loud) else x             # the speech, without the WAV's own quiet end
        alone.append(svc.recognizer.decode(np.concatenate([quiet(0.3), x, quiet(ending)])).decode_seconds)
        outbox = estopped if text == "stop" else launched
        before = len(outbox)
        send(np.concatenate([quiet(0.5), x]))
        while svc.streams.queued() > 0:
            time.sleep(0.002)
        time.sleep(0.02)                                      # the worker's last chunk
        t0 = time.perf_counter()
        send(quiet(ending))
        deadline = t0 + 2.0
        while len(outbox) == before and time.perf_counter() < deadline:
            time.sleep(0.0005)
        if len(outbox) > before:
            (to_stop if text == "stop" else to_launch).append(outbox[-1] - t0)
        else:
            missed += 1
    svc.close()
    bus.close()
    row(f"service: utterance end -> launch request on the bus ({len(to_launch)} utterances, memory bus)",
        np.array(to_launch), ref="from the chunk of quiet that ends it")
    row(f"service: utterance end -> estop latched ('stop', {len(to_stop)} utterances)", np.array(to_stop))
    row("  reference: recognising the same utterances alone", np.array(alone))
    ROWS.append(("  reference: the quiet that ends an utterance (VAD hangover)", f"{VadConfig().hangover * 1e3:.0f}",
                 f"{VadConfig().hangover * 1e3:.0f}", "ms", f"{missed} utterances not recognised (no launch)"))


def learning_rows(others: list[tuple[str, np.ndarray]]) -> None:
    """Each made-up word learned from one teacher's saying, then from each of the others (the
    page keeps up to three sayings); after the first and after the last, it is listened for in
    every saying of it that taught nothing, and in `others` (speech that is not it)."""
    folder = Path(tempfile.mkdtemp())
    sayings = {(word, voice, speed): microphone(speak(folder, word, voice, speed))
               for word in MADE_UP for voice, speed in {*itertools.product(VOICES, SPEEDS), *TEACHERS}}
    others = [(text, microphone(x)) for text, x in others]
    reader = phones.PhoneReader()
    learned, one_reading, choosing, durations = [], [], [], []
    heard = {1: 0, len(TEACHERS): 0}
    tried, refused, others_tried = 0, 0, 0
    try:
        for i, word in enumerate(MADE_UP):
            recognizer = Recognizer()
            learner = Learner(recognizer, Pronunciations(folder / f"pronunciations-{i}.json"),
                              lambda: list(ASSIGNED), reader)
            new = [(f"{w} ({v} {s})", x) for (w, v, s), x in sayings.items() if w == word and (v, s) not in TEACHERS]
            tried += len(new)
            for n, teacher in enumerate(TEACHERS, 1):
                recording = sayings[(word, *teacher)]
                if i == 0 and n == 1 and not QUICK:
                    learner.learn_recording(word, recording)      # starts the readers' processes (not counted)
                    learner.forget(word)
                t0 = time.perf_counter()
                learner.learn_recording(word, recording)
                learned.append(time.perf_counter() - t0)
                speech = speech_in(recording)
                durations.append(len(speech) / 16000)
                t0 = time.perf_counter()      # the reference: the child's own function, here, once
                phones._read(speech.tobytes(), reader.lw, reader.context_dependent)
                one_reading.append(time.perf_counter() - t0)
                readings = reader.readings(speech)
                t0 = time.perf_counter()
                learner.best_reading(word, readings, speech)
                choosing.append(time.perf_counter() - t0)
                if n not in heard:
                    continue
                recognizer.set_words([*ASSIGNED, word], skip_unknown=True, learned=learner.store.all())
                for said, x in new:
                    d = recognizer.decode(x)
                    heard[n] += d.heard is not None and d.heard.text == word
                    if n == len(TEACHERS) and (d.heard is None or d.heard.text != word):
                        LEARNING_MISSES.append(f"{said}: {d.reason or 'heard ' + repr(d.heard.text)}")
                if n == len(TEACHERS):
                    for text, x in others:
                        others_tried += 1
                        d = recognizer.decode(x)
                        refused += d.heard is None or d.heard.text != word
                        if d.heard is not None and d.heard.text == word:
                            LEARNING_MISSES.append(f"{text!r} (not {word}) heard as {word}")
    finally:
        reader.close()
        shutil.rmtree(folder)
    again = "; ".join(f"after {n} saying{'s' * (n > 1)}: heard in {h}/{tried} new sayings" for n, h in heard.items())
    row(f"learn a made-up word from one saying ({len(learned)} learned: {len(MADE_UP)} words x "
        f"{len(TEACHERS)} sayings)", np.array(learned), "s", again, scale=1)
    row("  reference: one phone-loop reading, in this process", np.array(one_reading), "s", scale=1)
    row("  reference: choosing between the readings (best_reading)", np.array(choosing))
    row("  reference: the saying's duration", np.array(durations), "s",
        f"other speech refused {refused}/{others_tried} (after the last saying)", scale=1)


def _rebuild_times(recognizer: Recognizer, words: list[str], lex: Lexicon) -> np.ndarray:
    # alternate two word lists, so that every call compiles (an unchanged grammar is skipped)
    lists = [words, words[:-1]]
    t = np.empty(reps(20))
    for i in range(len(t)):
        start = time.perf_counter()
        recognizer.set_grammar(build_grammar(lists[i % 2], lex))
        t[i] = time.perf_counter() - start
    return t


def print_rates(verdicts) -> None:
    """Recognition rates over the corpus, per voice, and the false accepts."""
    print("| voice | in grammar recognised | out of grammar refused |")
    print("|---|---|---|")
    for voice in VOICES + ["all"]:
        mine = [v for v in verdicts if voice in ("all", v[2])]
        inside = [v for v in mine if v[1]]
        outside = [v for v in mine if not v[1]]
        ok_in = sum(v[4].heard is not None and v[4].heard.text == v[0] for v in inside)
        ok_out = sum(v[4].heard is None for v in outside)
        print(f"| {voice} | {ok_in}/{len(inside)} | {ok_out}/{len(outside)} |")
    missed = [f"{v[0]!r} ({v[2]} {v[3]}): {v[4].reason}" for v in verdicts if v[1] and
              (v[4].heard is None or v[4].heard.text != v[0])]
    wrong = [f"{v[0]!r} ({v[2]} {v[3]}) -> {v[4].heard.text!r}" for v in verdicts if not v[1] and v[4].heard]
    print(f"\nfalse accepts ({len(wrong)}):", "; ".join(wrong) or "none")
    print(f"missed ({len(missed)}):")
    for m in missed:
        print("  ", m)


if __name__ == "__main__":
    main()
