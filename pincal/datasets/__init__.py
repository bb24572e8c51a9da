"""Measurement sets shipped with pincal, each with its provenance (README) and, if not pincal's own, licence.

``tiago_mocap``: two real Qualisys motion-capture sessions of a TIAGo arm; ``mukca``: real
socket-fixture sessions of a KUKA LBR iiwa 14 and a Franka Panda; ``lwr_bag``: a simulated KUKA
LWR 4+ session recorded as a ROS 2 bag (``scripts/make_example_bag.py``), for ``pincal extract``. In
a clone they are also under ``data/`` (a link to this folder); after ``pip install``, ``pincal
example NAME --out DIR`` copies one out (:mod:`pincal.workflows.example`).
"""
