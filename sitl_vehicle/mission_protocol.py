"""The MAVLink mission protocol, the vehicle's side: upload, download, clear, and the current item.

:class:`MissionProtocol` holds the ``_on_mission_*`` handlers of ``sitl_vehicle.mavlink_io.MavlinkVehicleInterface``
(a mixin: they use its ``commander``, ``home``, ``status_fn``, ``statustext``, ``_for_me`` and ``_upload``). An
upload is requested item by item and handed to the commander whole once every item was read
(:func:`sitl_vehicle.mission.mission_item_from_message`); only plans of type MISSION are kept. Apart from the rest
of the protocol because it is a conversation of its own, with its own state: the upload under way.
"""

from __future__ import annotations

import logging

from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.mission import MAX_ITEMS, MissionError, MissionItem, mission_item_from_message
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
        """Only plans of type MISSION are kept (no geofence or rally points): uploading others is refused
        clearly (their lists read as empty, and clearing them succeeds)."""
        mission_type = getattr(msg, "mission_type", mavlink.MAV_MISSION_TYPE_MISSION)
        if mission_type == mavlink.MAV_MISSION_TYPE_MISSION:
            return True
        if reply:
            self._mission_ack(link, msg, mavlink.MAV_MISSION_UNSUPPORTED, mission_type)
            self.statustext(mavlink.MAV_SEVERITY_WARNING, f"Mission type {mission_type} (geofence or rally points) "
                                                          "is not supported: only missions", link)
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
        if msg.count > MAX_ITEMS:
            self._mission_ack(link, msg, mavlink.MAV_MISSION_NO_SPACE)
            self.statustext(mavlink.MAV_SEVERITY_WARNING, f"Mission of {msg.count} items refused: at most "
                                                          f"{MAX_ITEMS}", link)
            return
        if msg.count == 0:
            self._upload = None
            self.commander.set_mission([], self.status_fn())
            self._mission_ack(link, msg, mavlink.MAV_MISSION_ACCEPTED)
            return
        self._upload = {"link": link, "count": msg.count, "items": []}  # a new COUNT restarts any upload
        self._request_item(link, msg, 0)

    def _request_item(self, link: UdpLink, msg, seq: int) -> None:
        link.send(mavlink.MAVLink_mission_request_int_message(msg.get_srcSystem(), msg.get_srcComponent(), seq,
                                                              mavlink.MAV_MISSION_TYPE_MISSION))

    def _on_mission_item_int(self, msg, link: UdpLink) -> None:
        if not self._for_me(msg) or not self._mission_type_ok(msg, link, reply=False):
            return
        upload = self._upload
        if upload is None or upload["link"] is not link:
            self._mission_ack(link, msg, mavlink.MAV_MISSION_DENIED)  # no upload under way: send MISSION_COUNT
            return
        expected = len(upload["items"])
        if msg.seq != expected:  # a repeat or a gap: ask again for the one we need
            self._request_item(link, msg, expected)
            return
        try:
            item = mission_item_from_message(msg, self.home.to_local)
        except MissionError as exc:
            self._upload = None
            log.warning("mission upload refused: %s", exc)
            self._mission_ack(link, msg, exc.result)
            self.statustext(mavlink.MAV_SEVERITY_WARNING, f"Mission refused: {exc}", link)
            return
        upload["items"].append(item)
        if len(upload["items"]) < upload["count"]:
            self._request_item(link, msg, expected + 1)
            return
        self._upload = None
        self.commander.set_mission(upload["items"], self.status_fn())
        self._mission_ack(link, msg, mavlink.MAV_MISSION_ACCEPTED)
        self.statustext(mavlink.MAV_SEVERITY_INFO, f"Mission accepted: {len(upload['items'])} items", link)

    _on_mission_item = _on_mission_item_int  # the older float form (lat/lon in degrees) is read the same way

    def _on_mission_request_list(self, msg, link: UdpLink) -> None:
        if not self._for_me(msg):
            return
        mission_type = getattr(msg, "mission_type", mavlink.MAV_MISSION_TYPE_MISSION)
        count = len(self.commander.mission) if mission_type == mavlink.MAV_MISSION_TYPE_MISSION else 0  # no fence
        link.send(mavlink.MAVLink_mission_count_message(msg.get_srcSystem(), msg.get_srcComponent(), count,
                                                        mission_type))

    def _on_mission_request_int(self, msg, link: UdpLink) -> None:
        if not self._for_me(msg) or not self._mission_type_ok(msg, link):
            return
        mission: tuple[MissionItem, ...] = self.commander.mission
        if not 0 <= msg.seq < len(mission):
            self._mission_ack(link, msg, mavlink.MAV_MISSION_INVALID_SEQUENCE)
            return
        # the float MISSION_REQUEST is answered in its own form, MISSION_ITEM, as the mission protocol says
        link.send(mission[msg.seq].to_message(msg.seq == self.commander.mission_seq, msg.get_srcSystem(),
                                              msg.get_srcComponent(), int_form=msg.get_type() != "MISSION_REQUEST"))

    _on_mission_request = _on_mission_request_int

    def _on_mission_clear_all(self, msg, link: UdpLink) -> None:
        if not self._for_me(msg):
            return
        mission_type = getattr(msg, "mission_type", mavlink.MAV_MISSION_TYPE_MISSION)
        if mission_type in (mavlink.MAV_MISSION_TYPE_MISSION, mavlink.MAV_MISSION_TYPE_ALL):
            self._upload = None
            self.commander.set_mission([], self.status_fn())
        self._mission_ack(link, msg, mavlink.MAV_MISSION_ACCEPTED, mission_type)  # no geofence or rally to clear

    def _on_mission_set_current(self, msg, link: UdpLink) -> None:
        if self._for_me(msg):
            if self.commander.set_mission_current(msg.seq, self.status_fn()).accepted:  # else it says why
                link.send(self._mission_current())
