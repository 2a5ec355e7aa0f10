"""The paper's Section 4: the well-stirred agent model (``model``), the Section 3
equations behind it (``equations``) and the ``swarm wellstirred`` command
(``command``). No robot uses any of it; the robots are in ``robot_agent``."""
