"""The mission events' names, values and texts on the wire, as the SITL sends them and clients read them.

Each event travels as a NAMED_VALUE_INT (:class:`EventName`, at most 10 characters; ``time_boot_ms`` = the step's
simulated time) and as a STATUSTEXT (:data:`RADAR_TEXTS`, :data:`IDENTIFIED_TEXT`, :data:`HIT_TEXT`,
:func:`mission_end_text`). The table of what each one means is in ``sim_vehicles/autopilot/events.py``.
"""

from __future__ import annotations

import enum


class EventName(enum.StrEnum):
    """NAMED_VALUE_INT names of the mission events."""

    RADAR_ON = "RADAR_ON"
    IDENT = "IDENT"
    HIT = "HIT"
    HAZARD = "HAZARD"
    FENCE = "FENCE"
    MSN_END = "MSN_END"


FLAGS = (EventName.RADAR_ON, EventName.IDENT, EventName.HIT, EventName.MSN_END)
"""The events whose current value is re-sent every second: a client that missed one learns it again."""


class MissionEnd(enum.IntEnum):
    """MSN_END values."""

    SUCCESS = 1
    GEOFENCE = 2
    EPISODE_CAP = 3

    @property
    def status(self) -> str:
        """The end's name in results and status files."""
        return {MissionEnd.SUCCESS: "success", MissionEnd.GEOFENCE: "geofence", MissionEnd.EPISODE_CAP: "episode_cap"}[
            self
        ]

    @property
    def text(self) -> str:
        """How the STATUSTEXT says it (after ``Mission end: ``)."""
        return {
            MissionEnd.SUCCESS: "success",
            MissionEnd.GEOFENCE: "geofence breach",
            MissionEnd.EPISODE_CAP: "episode cap",
        }[self]


RADAR_TEXTS = {True: "SAM radar ON", False: "SAM radar OFF"}
IDENTIFIED_TEXT = "Target identified"
HIT_TEXT = "Target hit"
MISSION_END_PREFIX = "Mission end: "


def mission_end_text(end: MissionEnd) -> str:
    return MISSION_END_PREFIX + end.text


def end_from_text(text: str) -> MissionEnd | None:
    """The end a ``Mission end: ...`` STATUSTEXT names (None for any other text or an unknown end)."""
    if not text.startswith(MISSION_END_PREFIX):
        return None
    said = text[len(MISSION_END_PREFIX) :]
    return next((end for end in MissionEnd if end.text == said), None)
