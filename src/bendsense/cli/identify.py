"""Commands of the identify area (see bendsense.cli)."""

COMMANDS = []
