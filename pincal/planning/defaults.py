"""The defaults and choices of ``pincal plan``: how many candidates are drawn, how many of them the
accuracy is averaged over, and the levels a plan can be made for.

Constants only, importing nothing: the command line's parser takes them from here without loading
the planner (numpy, scipy, Pinocchio).
"""

__all__ = ["DEFAULT_SAMPLE", "WORKSPACE_SIZE", "PLAN_LEVELS", "DEFAULT_AIMED"]

#: Configurations drawn when no candidate file is given.
DEFAULT_SAMPLE = 2000
#: Workspace configurations the accuracy is averaged over (a seeded subsample of the candidates).
WORKSPACE_SIZE = 500
#: What a plan can be made for: the levels of :func:`pincal.planning.information.plan_parameters`.
PLAN_LEVELS = ("registration", "offsets", "full", "dh")
#: A camera's plan: configurations aimed at the board by inverse kinematics when no candidate file is given,
#: and as many drawn within the joint limits (:func:`pincal.planning.camera_views.aimed_configurations`): a few
#: hundred usable views, among which the exchange's choice is within a few percent of the best of thousands
#: as for the sensors' plans.
DEFAULT_AIMED = 300
