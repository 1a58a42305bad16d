"""Serial ports present on this machine."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["PortInfo", "list_ports", "format_ports"]


@dataclass(frozen=True)
class PortInfo:
    """One serial port.

    Attributes
    ----------
    device : str
        Name to open (``/dev/ttyACM0``, ``COM3``).
    description : str
        Human-readable description from the OS.
    vid_pid : str
        USB ``VID:PID`` in hex (``"0483:5740"``), empty for non-USB ports.
    serial_number : str
        USB serial number, empty when unknown.
    manufacturer : str
        USB manufacturer, empty when unknown.
    """

    device: str
    description: str
    vid_pid: str
    serial_number: str
    manufacturer: str = ""


def list_ports() -> list[PortInfo]:
    """List the serial ports found by ``serial.tools.list_ports.comports()``, sorted by device name."""
    from serial.tools.list_ports import comports

    out = []
    for p in comports():
        vid_pid = f"{p.vid:04X}:{p.pid:04X}" if p.vid is not None and p.pid is not None else ""
        desc = p.description if p.description and p.description != "n/a" else ""
        out.append(PortInfo(p.device, desc, vid_pid, p.serial_number or "", p.manufacturer or ""))
    return sorted(out, key=lambda info: info.device)


def format_ports(ports) -> str:
    """Format a plain-text table of ``ports`` (or ``"no serial ports found"``).

    Parameters
    ----------
    ports : list of PortInfo
        The ports to list (:func:`list_ports`).
    """
    ports = list(ports)
    if not ports:
        return "no serial ports found"
    header = ("DEVICE", "VID:PID", "SERIAL", "DESCRIPTION")
    rows = [(p.device, p.vid_pid or "-", p.serial_number or "-", p.description or "-") for p in ports]
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(3)]
    lines = []
    for r in [header, *rows]:
        lines.append("  ".join(c.ljust(w) for c, w in zip(r[:3], widths, strict=True)) + "  " + r[3])
    return "\n".join(lines)
