"""SPaT transport: the store every trip reads (``store``: latest state per intersection and signal group, time
rules), its sources (``simulator``, ``scenarios``, the recorded-log reader and player ``recorded``/``player``,
``mqtt``, the remote-feed ``client``, ``pump``), the feed's FastAPI app (``service``) and the simulated
actuated controllers fitted on recordings (``actuated``). The top layer: imports ``timing``, ``road`` and
``prediction``.
"""
