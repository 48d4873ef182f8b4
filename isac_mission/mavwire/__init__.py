"""The MAVLink layer: the only package of the project that imports pymavlink.

Shared by the service's vehicle links (`isac_mission.service.bridge`) and the simulated PX4-like
vehicles (`sim.autopilot`), so both speak one dialect, one PX4 mode encoding, one signing and one
datagram parser with the same rejection reasons.

Modules, by job: `dialect` (MAVLink 2, common set, chosen before pymavlink is imported), `ports`
(loopback, PX4 SITL's port layout, MAVLink ids), `modes` (PX4 custom-mode encoding and decoding), `builders`
(pure message builders), `signing` (MAVLink 2 signing, encoders and packing), `parsing` (one
datagram parser and its rejection reasons), and the service's side of a link: `status` (what it
knows of the vehicle), `commands` (COMMAND_LONG and its ACK) and `link` (the asyncio
`MavlinkLink`); `serial_link` (link URLs, and MAVLink over a serial device for both sides).
"""
