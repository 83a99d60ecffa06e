"""The streamed `dynprop run` (``windows``' module doc): ``plan`` cuts the run into
windows, ``producer`` flies the truth, senses it and runs the linear twin and its
filter (``twin_filter``) in a process of its own (``process``, ``handoff``),
``stages`` filter and smooth each window, ``windows`` joins them in order, and
``directory`` accumulates the tallies (``run``'s ``tally``, ``daily``,
``filter_tally``) and writes the run directory.

Part of the ``run`` room: may import what ``run`` may.
"""
