"""The MAVLink edge of the service; the core never sees MAVLink.

================  ==============================================================
:mod:`.link`      serial, UDP and TCP byte transports
:mod:`.framing`   bytes -> frames, resynchronising after corruption
:mod:`.messages`  a frame -> its message object (pymavlink's, or a light tuple)
:mod:`.tlog`      .tlog files: records of (time, frame), read robustly, written
:mod:`.decode`    messages -> typed samples (clock, validation, counting)
:mod:`.encode`    typed outputs -> messages -> frames
:mod:`.readback`  our own published messages -> typed values (evaluate, console)
:mod:`.streams`   stream requests to the autopilot and the received rates
:mod:`.signing`   MAVLink 2 signing of a link: our frames signed, the peer's checked
:mod:`.ids`       message ids and enum values; :mod:`.units` the field scalings;
                  :mod:`.dialect` the pymavlink dialect module
================  ==============================================================

See ``docs/mavlink.md`` for the messages in and out.
"""
