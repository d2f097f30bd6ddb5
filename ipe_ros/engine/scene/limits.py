"""What the engine accepts: physical validity ranges, each with the one-line reason for it.

A value outside these is refused where it enters (scene validation, model settings) with a message
naming the field, the range and the fix, instead of being simulated into a wrong answer or a
stall. benchmarks/limits.py measures the reasons given here; docs/scene-format.md lists them.
"""

from __future__ import annotations

#: Smallest extent of any body. Steps shrink with sqrt(size / g): 1 mm needs 0.4 ms steps (5,000
#: per 2 s rollout); at 0.2 mm a standing two-cube stack fell (benchmarks/limits.py).
MIN_SIZE_M = 1e-3
#: Largest extent of any body. Measured: at 20 m a standing two-cube stack fell and ended 27% of its
#: size inside the other, at 50-100 m a leaning one had not fallen within the 2 s horizon.
MAX_SIZE_M = 10.0
#: Every coordinate (positions, support heights, table centres). pybullet computes in doubles: a
#: stack 10 km from the origin ends within 5e-11 of its size of the same stack at the origin; at
#: 1e15 m its outcome changed (benchmarks/limits.py).
MAX_COORDINATE_M = 1e4
#: Linear speed at t = 0. The travel limit cuts a step into at most 32 substeps: 100 m/s keeps a
#: 1 mm body within that at its own step, and faster objects are projectiles, not scenes.
MAX_SPEED_M_S = 100.0
#: Spin at t = 0, for the same reason (a corner's speed is spin x half diagonal).
MAX_SPIN_RAD_S = 1000.0
#: Mass of one body. Only ratios matter to the solver; the bounds catch unit mistakes (grams as kg).
MIN_MASS_KG = 1e-6
MAX_MASS_KG = 1e6
#: Heaviest over lightest dynamic body (the scene's own masses, before mu). The catalogue tests up
#: to 1000:1; at 10,000:1 ``default`` topples a heavy-on-light stack that ``paper`` keeps standing.
MAX_MASS_RATIO = 1000.0
#: Friction coefficient (pybullet multiplies the two bodies'). Above ~2 nothing slides any more.
MAX_FRICTION = 10.0
#: |gravity|. The step scales with sqrt(size / g); from the Moon's 1.6 to ~10 g with margin both
#: ways. Zero gravity has no "fall", and 1e8 m/s^2 needs steps of microseconds.
MIN_GRAVITY_M_S2 = 0.1
MAX_GRAVITY_M_S2 = 100.0
#: Position noise SD (model sigma and a body's own). Perception is never metres off; larger
#: values are unit mistakes (mm as m).
MAX_SIGMA_M = 10.0
#: Latent push phi (the support's horizontal acceleration): 10 g.
MAX_PHI_M_S2 = 100.0
#: Points of one convex hull. pybullet builds the hull in every rollout's world and tests contacts
#: against its vertices: a 100,000-point hull ran a 10 s budget over by 2-4 s before the deadline
#: could act. A robot's mesh decimated to ~100-1000 points loses nothing at the 1 mm scale.
MAX_HULL_VERTICES = 1024
#: Parts of one compound (the zoo's bowls and rings have 10-11), and hull points over all of them.
MAX_COMPOUND_PARTS = 256
MAX_COMPOUND_VERTICES = 4096
#: Variants one question may ask about (place spots, or a region's candidates x yaws): each is one
#: more simulated scene per sample, and each placement is first lowered onto what is below it
#: (~2-8 ms of geometry). More is a search for a planner to run, not one question.
MAX_QUESTION_VARIANTS = 400
#: Characters of a name (scene, object, group).
MAX_NAME_CHARS = 256
#: Characters of a JSON scene text (a 200-object scene is ~60 kB).
MAX_JSON_CHARS = 16_000_000
