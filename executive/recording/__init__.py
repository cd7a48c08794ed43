"""Foxglove and MCAP (issue 13): the run's live state on Foxglove's well-known schemas.

* :mod:`.channels`: the channels, their schemas and :class:`~.channels.Recorder`, the
  stream sink that encodes the run's records and robot state onto them;
* :mod:`.mcapfile`: MCAP files of those channels (``--mcap``), written with ``mcap``;
* :mod:`.foxglove_server`: the live Foxglove WebSocket server (``--foxglove``), foxglove-sdk;
* :mod:`.session`: both attached to a ``run`` or ``serve`` runner's streams;
* :mod:`.export`: ``mmexec log export``, an event log as an MCAP file;
* :mod:`.layout`: the Foxglove layout shipped as ``docs/foxglove/mmexec-layout.json``.

docs/foxglove.md is the user's guide.
"""
