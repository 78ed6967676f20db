"""KUKA EthernetKRL: the EKI configuration file, the XML frames, and the KRL program.

The robot controller is the EKI endpoint the PC connects to: the configuration's
``EXTERNAL`` names the PC (a client), ``INTERNAL`` the robot side (port, buffering, the
flag raised when a frame is complete). Each frame the PC streams is::

    <Robot><Pos A1="…" A2="…" A3="…" A4="…" A5="…" A6="…" T="…"/><Gripper Close="0|1"/></Robot>

with axis angles in degrees and T the time (s from the start of the path) at which the
point is due. A frame whose A1 is empty ends the program, as in the paper's Table 1.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from xml.sax.saxutils import escape, quoteattr

AXES = ("A1", "A2", "A3", "A4", "A5", "A6")
# A RECEIVE element hycosim reads: an attribute of the frame's Robot element or of one below it
# (EKI can also carry an element's text; the frames here carry none).
_ATTRIBUTE_TAG = re.compile(r"Robot(/[A-Za-z_][A-Za-z0-9_.\-]*)*/@[A-Za-z_][A-Za-z0-9_.\-]*")
FLAGS = range(1, 1025)  # KRL's $FLAG[1] … $FLAG[1024]


class EkiError(ValueError):
    """An EKI configuration or frame that does not follow the format; says what and where."""


@dataclass
class EkiConfig:
    """An EthernetKRL configuration: its name, the PC's and the controller's IPs, the port, and the
    elements each frame carries (the six axes, the time, the gripper)."""

    name: str = "HycosimGrasp"
    external_ip: str = "192.168.1.10"   # the PC streaming the path
    internal_ip: str = "192.168.1.147"  # the robot controller
    port: int = 54600
    flag: int = 1
    elements: list[tuple[str, str]] = field(default_factory=lambda: [
        *((f"Robot/Pos/@{a}", "REAL") for a in AXES), ("Robot/Pos/@T", "REAL"), ("Robot/Gripper/@Close", "BOOL")])

    def to_xml(self) -> str:
        """The configuration as the controller's EKI XML file."""
        # quoted: a configuration read from a file may hold any text in its IPs and Tags
        elements = "\n".join(f"      <ELEMENT Tag={quoteattr(tag)} Type={quoteattr(typ)}/>" for tag, typ in self.elements)
        return f"""<ETHERNETKRL>
  <CONFIGURATION>
    <EXTERNAL>
      <IP>{escape(self.external_ip)}</IP>
      <PORT>{self.port}</PORT>
      <TYPE>Client</TYPE>
    </EXTERNAL>
    <INTERNAL>
      <ENVIRONMENT>Program</ENVIRONMENT>
      <BUFFERING Mode="FIFO" Limit="512"/>
      <ALIVE Set_Flag="{self.flag + 1}"/>
      <IP>{escape(self.internal_ip)}</IP>
      <PORT>{self.port}</PORT>
      <PROTOCOL>TCP</PROTOCOL>
    </INTERNAL>
  </CONFIGURATION>
  <RECEIVE>
    <XML>
{elements}
      <ELEMENT Tag="Robot" Set_Flag="{self.flag}"/>
    </XML>
  </RECEIVE>
  <SEND>
    <XML>
      <ELEMENT Tag="Robot/Ack"/>
    </XML>
  </SEND>
</ETHERNETKRL>
"""

    @staticmethod
    def parse(text: str | bytes, source: str = "<eki>") -> "EkiConfig":
        """The configuration in ``text`` (bytes: decoded as the XML declares, UTF-8 by default);
        EkiError naming ``source`` and what is wrong."""
        try:
            root = ET.fromstring(text)
        except ET.ParseError as exc:
            raise EkiError(f"{source}: not XML ({exc})") from None
        if root.tag != "ETHERNETKRL":
            raise EkiError(f"{source}: root element is <{root.tag}>, expected <ETHERNETKRL>")
        internal = root.find("CONFIGURATION/INTERNAL")
        external = root.find("CONFIGURATION/EXTERNAL")
        if internal is None or external is None:
            raise EkiError(f"{source}: CONFIGURATION needs EXTERNAL and INTERNAL")
        port_text = (internal.findtext("PORT") or external.findtext("PORT") or "").strip()
        if not re.fullmatch(r"[0-9]{1,5}", port_text) or not 1 <= int(port_text) <= 65535:
            raise EkiError(f"{source}: INTERNAL/PORT {port_text[:20]!r} is not a port number (1-65535)")
        port = int(port_text)
        elements = []
        flag = 1
        for el in root.findall("RECEIVE/XML/ELEMENT"):
            tag = el.get("Tag")
            if tag is None:
                raise EkiError(f"{source}: RECEIVE element without Tag")
            if el.get("Set_Flag"):
                given = el.get("Set_Flag", "").strip()
                if not re.fullmatch(r"[0-9]{1,4}", given) or int(given) not in FLAGS:
                    raise EkiError(f"{source}: element {tag[:60]!r} has Set_Flag {given[:20]!r}, "
                                   f"not a flag number ({FLAGS.start}-{FLAGS.stop - 1})")
                flag = int(given)
                continue
            typ = el.get("Type")
            if typ not in ("REAL", "INT", "BOOL", "STRING"):
                raise EkiError(f"{source}: element {tag[:60]!r} has Type {typ!r}")
            if not _ATTRIBUTE_TAG.fullmatch(tag):
                raise EkiError(f"{source}: element {tag[:60]!r} is not an attribute of the Robot frame "
                               "(Robot/…/@NAME), the only values hycosim's frames carry")
            elements.append((tag, typ))
        missing = [a for a in AXES if (f"Robot/Pos/@{a}", "REAL") not in elements]
        if missing:
            raise EkiError(f"{source}: RECEIVE lacks REAL elements for {', '.join(missing)}")
        return EkiConfig(name=Path(source).stem if source != "<eki>" else "eki",
                         external_ip=(external.findtext("IP") or "").strip(),
                         internal_ip=(internal.findtext("IP") or "").strip(), port=port, flag=flag, elements=elements)


def frame(q_deg: list[float] | None, t: float = 0.0, close: bool = False) -> str:
    """One XML frame; ``q_deg=None`` gives the empty-A1 frame that ends the program."""
    if q_deg is None:
        return '<Robot><Pos A1="" A2="" A3="" A4="" A5="" A6="" T=""/><Gripper Close="0"/></Robot>'
    axes = " ".join(f'{a}="{v:.4f}"' for a, v in zip(AXES, q_deg))
    return f'<Robot><Pos {axes} T="{t:.4f}"/><Gripper Close="{int(close)}"/></Robot>'


@dataclass
class Frame:
    """One frame of the path: the axes in degrees (None: the program ends), the time to reach them and
    whether the gripper closes."""

    q_deg: list[float] | None  # None: the program ends
    t: float
    close: bool


def parse_frame(text: str, config: EkiConfig) -> Frame:
    """Values per the configuration's RECEIVE elements; EkiError on anything malformed."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise EkiError(f"malformed XML frame ({exc})") from None
    if root.tag != "Robot":
        raise EkiError(f"frame root is <{root.tag}>, expected <Robot>")
    values: dict[str, str | None] = {}
    for tag, _ in config.elements:
        path, _, attr = tag.partition("/@")
        node = root if path == "Robot" else root.find(path.split("/", 1)[1])
        values[tag] = None if node is None else node.get(attr)
    a1 = values.get("Robot/Pos/@A1")
    if a1 is None or a1.strip() == "":
        return Frame(None, 0.0, False)
    parsed: dict[str, float | bool] = {}
    for tag, typ in config.elements:
        raw = values[tag]
        if raw is None:
            raise EkiError(f"frame lacks {tag}")
        try:
            parsed[tag] = raw.strip() in ("1", "TRUE", "true") if typ == "BOOL" else float(raw)
        except ValueError:
            raise EkiError(f"{tag}={raw!r} is not {typ}") from None
    return Frame([float(parsed[f"Robot/Pos/@{a}"]) for a in AXES], float(parsed.get("Robot/Pos/@T", 0.0)),
                 bool(parsed.get("Robot/Gripper/@Close", False)))


def krl_program(config: EkiConfig, home_deg: tuple[float, ...]) -> str:
    """The KRL program of the paper's Table 1, receiving A1…A6 per frame over EthernetKRL."""
    n = config.name
    home = ", ".join(f"{a} {v:.4f}" for a, v in zip(AXES, home_deg))
    gets = "\n".join(f'    RET = EKI_GetReal("{n}", "Robot/Pos/@{a}", XP1.{a})' for a in AXES[1:])
    return f"""&ACCESS RVP
DEF {n}()
  ; Generated by hycosim (`hycosim krl export`): the paper's Table 1 loop.
  DECL EKI_STATUS RET
  DECL E6AXIS XP1          ; six axes A1~A6, initialised to the initial position
  DECL REAL T, A1
  DECL BOOL CLOSE
  INI
  XP1 = {{{home}}}
  PTP XP1                  ; move point-to-point to the initial position (reset)
  RET = EKI_Init("{n}")    ; initialise and open the XML channel (TCP)
  RET = EKI_Open("{n}")
  $TIMER[1] = 0
  $TIMER_STOP[1] = FALSE
  LOOP
    WAIT FOR $FLAG[{config.flag}]          ; a complete frame arrived
    $FLAG[{config.flag}] = FALSE
    RET = EKI_GetReal("{n}", "Robot/Pos/@A1", A1)
    IF RET.Buff == 0 THEN                  ; the received A1 is empty: leave the loop
      EXIT
    ENDIF
    XP1.A1 = A1
{gets}
    RET = EKI_GetReal("{n}", "Robot/Pos/@T", T)
    RET = EKI_GetBool("{n}", "Robot/Gripper/@Close", CLOSE)
    WAIT FOR $TIMER[1] >= T * 1000         ; keep the path's timing
    PTP XP1 C_PTP                          ; point-to-point to XP1
    $OUT[1] = CLOSE                        ; gripper closes (TRUE) or opens (FALSE)
  ENDLOOP
  RET = EKI_Close("{n}")
  RET = EKI_Clear("{n}")
END
"""
