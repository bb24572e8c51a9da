"""The defaults and choices of ``pincal plan``: how many candidates are drawn, how many of them the
accuracy is averaged over, and the levels a plan can be made for.

Constants only, importing nothing: the command line's parser takes them from here without loading
the planner (numpy, scipy, Pinocchio).
"""

__all__ = ["DEFAULT_SAMPLE", "WORKSPACE_SIZE", "PLAN_LEVELS"]

#: Configurations drawn when no candidate file is given.
DEFAULT_SAMPLE = 2000
#: Workspace configurations the accuracy is averaged over (a seeded subsample of the candidates).
WORKSPACE_SIZE = 500
#: What a plan can be made for: the levels of :func:`pincal.planning.information.plan_parameters`.
PLAN_LEVELS = ("registration", "offsets", "full", "dh")
