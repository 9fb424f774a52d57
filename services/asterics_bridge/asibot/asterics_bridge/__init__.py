"""The AsTeRICS bridge: AsTeRICS NetConnection, plain text and HTTP clients drive the robots
through one command vocabulary and hear back what happens (docs/asterics.md)."""
