"""Commands of the sim area (see bendsense.cli)."""

COMMANDS = []
