"""Real measurement sets shipped with pincal, each with its provenance and licence (README, LICENSE).

``tiago_mocap``: two Qualisys motion-capture sessions of a TIAGo arm; ``mukca``: socket-fixture
sessions of a KUKA LBR iiwa 14 and a Franka Panda. In a clone they are also under ``data/`` (a link
to this folder); after ``pip install``, ``pincal example NAME --out DIR`` copies one out
(:mod:`pincal.cli.example`).
"""
