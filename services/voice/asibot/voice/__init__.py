"""Offline voice commands: audio in, VAD, a pocketsphinx grammar of the user's words, espeak-ng out.

Plain logic, no bus (docs/voice.md): audio, vad, grammar, recognizer, speaker, errors, and for
the service streams (sources to utterances), commands (what a heard word does), mic (the local
microphone); `service` puts them on the bus (`python -m asibot.voice`).
"""
