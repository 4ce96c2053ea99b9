"""The schedule flag's words, without numpy or bags: `zeus collect/loop --help` print them.

offline/rollout.py (parse_schedule) re-exports both; they live here so that a --help answers
before the rollout code and its imports load (issue 52).
"""

from __future__ import annotations

__all__ = ['DEFAULT_SCHEDULE', 'SCHEDULE_HELP']

DEFAULT_SCHEDULE = 'switch:train:every_episodes=1'
"""What `zeus loop` and `zeus sweep` collect with unless told: one train value per episode, in
turn (docs/results.md, session 7: the critic can value a context that holds for the episode)."""
SCHEDULE_HELP = """\
context schedule: a YAML file (as accepted by sim_bridge.schedules.schedule_from_config), or
the inline form KIND[:PRESET][:KEY=VALUE[,KEY=VALUE...]] where KIND is a schedule kind
(constant, switch, drift, random_walk), PRESET names a preset split of the family (train,
interpolation, extrapolation; it becomes `values`) and KEY=VALUE are the kind's options, e.g.
  constant                                the task's default context, never changing
  constant:value=0.8                      one fixed value
  switch:train:every=100                  cycle through the train preset every 100 steps
  switch:train:every_episodes=1,order=sample   a sampled train value per episode
  drift:shape=sinusoid,low=0.6,high=1.2,period=500
  random_walk:low=0.4,high=1.4,step_size=0.02
Numbers in VALUE are parsed as YAML scalars (100 -> int, 0.5 -> float)."""
