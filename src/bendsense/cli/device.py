"""Commands of the device area (see bendsense.cli)."""

COMMANDS = []
