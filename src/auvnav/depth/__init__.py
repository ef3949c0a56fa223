"""Depth: pressure to depth, tides and the datum correction (DESIGN sections 1.3 and 4).

- :mod:`auvnav.depth.pressure`: sea pressure (atmospheric constant or series), TEOS-10 depth,
  UNESCO 1983 depth for comparison with older processing.
- :mod:`auvnav.depth.tide`: tide models from harmonic constituents (utide), their CSV file, harmonic
  analysis of a gauge record, depth below the datum.
- :mod:`auvnav.depth.estimation`: the tide estimated from loop closures alone.
- :mod:`auvnav.depth.validation`: pressure depth checked against the vertical of loop closures (Fig. 6).
- :mod:`auvnav.depth.stage`: the ``auvnav depth`` stage; :mod:`auvnav.depth.evaluate`: its products
  against a simulated dive's true tide.
"""
