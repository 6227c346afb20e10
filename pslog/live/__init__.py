"""Live mode: camera processes send detection datagrams over UDP, a live fuser emits a 3D
point at every shutter as its detection arrives (docs/live.md).

- :mod:`pslog.live.protocol`: the versioned binary datagrams (detections in, points out);
- :mod:`pslog.live.fuser`: :class:`~pslog.live.fuser.LiveFuser`, bytes in, points out, every
  bad datagram counted and dropped;
- :mod:`pslog.live.server`: :func:`~pslog.live.server.serve`, the UDP loop feeding the fuser
  and handing each point to the sinks at once;
- :mod:`pslog.live.sinks`: the outputs (:class:`~pslog.live.sinks.UdpSink`,
  :class:`~pslog.live.sinks.JsonlSink`, :class:`~pslog.live.sinks.RecordSink`).
"""
