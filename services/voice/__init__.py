"""Offline voice commands: audio in, VAD, a pocketsphinx grammar of the user's words, espeak-ng out.

Plain logic, no bus (docs/voice.md): audio, vad, grammar, recognizer, speaker, errors.
"""
