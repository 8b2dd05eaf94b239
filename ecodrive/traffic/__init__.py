"""Traffic: a corridor's lights and cars in Eclipse SUMO, the connected cars advised through the service's own path.

* :mod:`ecodrive.traffic.network`: a corridor (any :class:`~spat_feed.road.corridors.Corridor`: the paper's, an OSM
  import) becomes a SUMO network (plain XML nodes, edges, connections and traffic-light programs, built by SUMO's
  ``netconvert``), its lights SUMO traffic lights at the stop-line stations, fixed-time from the corridor's plan or
  SUMO's own actuated controller; background traffic as SUMO flows at a demand per lane.
* :mod:`spat_feed.transport.sumo`: SUMO's lights as J2735 SPaT, offered to the service's store.
* :mod:`ecodrive.traffic.driver`: the virtual driver of a connected car (1 s reaction, comfortable rates, its own eyes).
* :mod:`ecodrive.traffic.sim`: one simulation run (advised by ecodrive, SUMO's GLOSA device, or unadvised).
* :mod:`ecodrive.traffic_eval`: ``ecodrive traffic-eval``, the three runs paired on the same seed and demand.

SUMO comes from PyPI (``eclipse-sumo``, ``libsumo``; the ``traffic`` extra, installed with ``test``). docs/TRAFFIC.md.
"""
