"""Applications: whole programs built on the library, each behind one ``bendsense`` command.

The library (frames → session → calibration → pcc → actuator → beam → estimation →
pipeline, with ``device``, ``sim``, ``plots`` and ``interop``) never imports from here;
an application imports from the library and adds what a program needs around it: a
window, a protocol of experiments, a report.

- :mod:`~bendsense.apps.live_view`: the live window of ``bendsense live`` (shape, force
  arrow, channel levels and a scrolling force plot, blitted) around
  :class:`bendsense.pipeline.LiveProcessor`;
- :mod:`~bendsense.apps.demo`: ``bendsense demo``, the whole chain on a simulated board
  checked against the simulated truth;
- :mod:`~bendsense.apps.evaluation`: ``bendsense reproduce``, the paper's evaluation on
  simulated experiments (published numbers, protocol, metrics, figures, report).

A new application is a module (or a package, when it has parts) here and a command in
:mod:`bendsense.cli` that calls it.
"""
