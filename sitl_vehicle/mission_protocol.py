"""The MAVLink mission protocol, the vehicle's side: upload, download, clear, and the current item.

:class:`MissionProtocol` holds the ``_on_mission_*`` handlers of ``sitl_vehicle.mavlink_io.MavlinkVehicleInterface``
(a mixin: they use its ``commander``, ``home``, ``status_fn``, ``statustext``, ``_for_me`` and ``_upload``). An
upload is requested item by item and handed to the commander whole once every item was read
(:func:`sitl_vehicle.mission.mission_item_from_message`; for a plan of type FENCE
:func:`sitl_vehicle.geofence.fence_item_from_message` and :func:`~sitl_vehicle.geofence.geofence_from_items`; for
RALLY :func:`~sitl_vehicle.geofence.rally_item_from_message`). Apart from the rest of the protocol because it is a
conversation of its own, with its own state: the upload under way.
"""

from __future__ import annotations

import logging

from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.geofence import (
    FENCE,
    RALLY,
    Geofence,
    PlacedItem,
    fence_item_from_message,
    geofence_from_items,
    rally_item_from_message,
)
from sitl_vehicle.mission import (
    MAX_ITEMS,
    MissionError,
    MissionItem,
    check_mission,
    mission_item_from_message,
    passed_items_note,
)
from sitl_vehicle.modes import FlightMode
from sitl_vehicle.udp_link import UdpLink

# the logger these lines had before the mission protocol had a module of its own
log = logging.getLogger("sitl_vehicle.mavlink_io")


class MissionProtocol:
    """The mission protocol's handlers, mixed into ``MavlinkVehicleInterface``."""

    def _mission_ack(self, link: UdpLink, msg, result: int, mission_type: int = mavlink.MAV_MISSION_TYPE_MISSION):
        link.send(mavlink.MAVLink_mission_ack_message(msg.get_srcSystem(), msg.get_srcComponent(), result,
                                                      mission_type))

    def _mission_type_ok(self, msg, link: UdpLink, reply: bool = True) -> bool:
        """Plans of type MISSION, FENCE and RALLY are kept; another type is refused clearly."""
        mission_type = getattr(msg, "mission_type", mavlink.MAV_MISSION_TYPE_MISSION)
        if mission_type in (mavlink.MAV_MISSION_TYPE_MISSION, FENCE, RALLY):
            return True
        if reply:
            self._mission_ack(link, msg, mavlink.MAV_MISSION_UNSUPPORTED, mission_type)
            self.statustext(mavlink.MAV_SEVERITY_WARNING, f"Mission type {mission_type} is not supported: send a "
                                                          "mission (0), a geofence (1) or rally points (2)", link)
        return False

    def _mission_current(self):
        c = self.commander
        if not c.mission:
            state = mavlink.MISSION_STATE_NO_MISSION
        elif c.mission_finished:
            state = mavlink.MISSION_STATE_COMPLETE
        elif c.mode is FlightMode.AUTO_MISSION:
            state = mavlink.MISSION_STATE_ACTIVE
        else:
            state = mavlink.MISSION_STATE_NOT_STARTED if c.mission_seq == 0 else mavlink.MISSION_STATE_PAUSED
        return mavlink.MAVLink_mission_current_message(c.mission_seq, len(c.mission), state, 0)

    def _on_mission_count(self, msg, link: UdpLink) -> None:
        if not self._for_me(msg) or not self._mission_type_ok(msg, link):
            return
        mission_type = getattr(msg, "mission_type", mavlink.MAV_MISSION_TYPE_MISSION)
        if msg.count > MAX_ITEMS:
            self._mission_ack(link, msg, mavlink.MAV_MISSION_NO_SPACE, mission_type)
            self.statustext(mavlink.MAV_SEVERITY_WARNING, f"{_plan(mission_type)} of {msg.count} items refused: "
                                                          f"at most {MAX_ITEMS}", link)
            return
        if msg.count == 0:
            self._upload = None
            self._keep(mission_type, [])
            self._mission_ack(link, msg, mavlink.MAV_MISSION_ACCEPTED, mission_type)
            return
        # a new COUNT restarts any upload
        self._upload = {"link": link, "count": msg.count, "items": [], "type": mission_type}
        self._request_item(link, msg, 0, mission_type)

    def _keep(self, mission_type: int, items: list) -> None:
        """Hand an uploaded plan to the commander (raises MissionError for a fence whose items make no zones)."""
        if mission_type == FENCE:
            self.commander.set_geofence(geofence_from_items(items) if items else Geofence())
        elif mission_type == RALLY:
            self.commander.set_rally_points(items)
        else:
            self.commander.set_mission(items, self.status_fn())

    def _plan_items(self, mission_type: int) -> tuple[MissionItem, ...] | tuple[PlacedItem, ...]:
        """The items of the commander's plan of ``mission_type``, as uploaded (none for another type)."""
        c = self.commander
        return {mavlink.MAV_MISSION_TYPE_MISSION: c.mission, FENCE: c.geofence.items, RALLY: c.rally_points}.get(
            mission_type, ())

    def _request_item(self, link: UdpLink, msg, seq: int, mission_type: int) -> None:
        link.send(mavlink.MAVLink_mission_request_int_message(msg.get_srcSystem(), msg.get_srcComponent(), seq,
                                                              mission_type))

    def _on_mission_item_int(self, msg, link: UdpLink) -> None:
        if not self._for_me(msg) or not self._mission_type_ok(msg, link, reply=False):
            return
        upload = self._upload
        mission_type = getattr(msg, "mission_type", mavlink.MAV_MISSION_TYPE_MISSION)
        if upload is None or upload["link"] is not link or upload["type"] != mission_type:
            # no upload of this plan under way: send MISSION_COUNT first
            self._mission_ack(link, msg, mavlink.MAV_MISSION_DENIED, mission_type)
            return
        expected = len(upload["items"])
        if msg.seq != expected:  # a repeat or a gap: ask again for the one we need
            self._request_item(link, msg, expected, mission_type)
            return
        read = {FENCE: fence_item_from_message, RALLY: rally_item_from_message}.get(mission_type,
                                                                                   mission_item_from_message)
        try:
            upload["items"].append(read(msg, self.home.to_local))
            if len(upload["items"]) == upload["count"]:
                self._upload = None
                if mission_type == mavlink.MAV_MISSION_TYPE_MISSION:
                    check_mission(upload["items"])
                self._keep(mission_type, upload["items"])
        except MissionError as exc:
            self._upload = None
            log.warning("%s upload refused: %s", _plan(mission_type).lower(), exc)
            self._mission_ack(link, msg, exc.result, mission_type)
            self.statustext(mavlink.MAV_SEVERITY_WARNING, f"{_plan(mission_type)} refused: {exc}", link)
            return
        if len(upload["items"]) < upload["count"]:
            self._request_item(link, msg, expected + 1, mission_type)
            return
        self._mission_ack(link, msg, mavlink.MAV_MISSION_ACCEPTED, mission_type)
        self.statustext(mavlink.MAV_SEVERITY_INFO, f"{_plan(mission_type)} accepted: {len(upload['items'])} items",
                        link)
        note = passed_items_note(upload["items"]) if mission_type == mavlink.MAV_MISSION_TYPE_MISSION else None
        if note:
            log.info("%s", note)
            self.statustext(mavlink.MAV_SEVERITY_INFO, note, link)

    _on_mission_item = _on_mission_item_int  # the older float form (lat/lon in degrees) is read the same way

    def _on_mission_request_list(self, msg, link: UdpLink) -> None:
        if not self._for_me(msg):
            return
        mission_type = getattr(msg, "mission_type", mavlink.MAV_MISSION_TYPE_MISSION)
        count = len(self._plan_items(mission_type))
        link.send(mavlink.MAVLink_mission_count_message(msg.get_srcSystem(), msg.get_srcComponent(), count,
                                                        mission_type))

    def _on_mission_request_int(self, msg, link: UdpLink) -> None:
        if not self._for_me(msg) or not self._mission_type_ok(msg, link):
            return
        mission_type = getattr(msg, "mission_type", mavlink.MAV_MISSION_TYPE_MISSION)
        plan = self._plan_items(mission_type)
        if not 0 <= msg.seq < len(plan):
            self._mission_ack(link, msg, mavlink.MAV_MISSION_INVALID_SEQUENCE, mission_type)
            return
        # the float MISSION_REQUEST is answered in its own form, MISSION_ITEM, as the mission protocol says
        int_form = msg.get_type() != "MISSION_REQUEST"
        if mission_type != mavlink.MAV_MISSION_TYPE_MISSION:
            link.send(plan[msg.seq].to_message(msg.get_srcSystem(), msg.get_srcComponent(), int_form))
        else:
            link.send(plan[msg.seq].to_message(msg.seq == self.commander.mission_seq, msg.get_srcSystem(),
                                               msg.get_srcComponent(), int_form=int_form))

    _on_mission_request = _on_mission_request_int

    def _on_mission_clear_all(self, msg, link: UdpLink) -> None:
        if not self._for_me(msg):
            return
        mission_type = getattr(msg, "mission_type", mavlink.MAV_MISSION_TYPE_MISSION)
        if mission_type in (mavlink.MAV_MISSION_TYPE_MISSION, mavlink.MAV_MISSION_TYPE_ALL):
            self._upload = None
            self.commander.set_mission([], self.status_fn())
        if mission_type in (FENCE, mavlink.MAV_MISSION_TYPE_ALL):
            self._upload = None
            self.commander.set_geofence(Geofence())
        if mission_type in (RALLY, mavlink.MAV_MISSION_TYPE_ALL):
            self._upload = None
            self.commander.set_rally_points([])
        self._mission_ack(link, msg, mavlink.MAV_MISSION_ACCEPTED, mission_type)

    def _on_mission_set_current(self, msg, link: UdpLink) -> None:
        if self._for_me(msg):
            if self.commander.set_mission_current(msg.seq, self.status_fn()).accepted:  # else it says why
                link.send(self._mission_current())


def _plan(mission_type: int) -> str:
    """What a plan of ``mission_type`` is called in the vehicle's messages."""
    return {FENCE: "Geofence", RALLY: "Rally points"}.get(mission_type, "Mission")
