"""Questions about a robot's own next action: remove, place or push an object, and what follows.

Every question is a set of *variants* of one scene (the scene as it is, without object i, with a
new object here, with object j pushed) answered by the same Monte Carlo IPE. Variants share their
random numbers: sample s of every variant starts from the same noisy, separated scene (drawn and
de-penetrated once, from the s-th child seed), so the difference between "remove block 3" and
"remove block 5" is the removal's, not Monte Carlo noise. A variant that adds something draws the
added randomness (where the new object lands, how hard the push is) from a second stream of the same
seed, leaving the shared draw untouched.

``ask`` runs variants; ``remove``, ``support_graph``, ``clear_order``, ``place``, ``best_place`` and
``push`` are the questions built on it. A removal that cannot change anything (nothing else is
within the removed objects' reach, ``groups``) is answered from the scene's own samples without
simulating, and says so (``simulated: False``). Each variant's answer is given twice: over all
samples, and over the samples in which the scene as it is stands (``given_stands``), so that what
an action makes fall is not confused with what falls anyway.

The package, one job per module: kinds.py (what a robot may do: Remove, Place, Push, Region),
geometry.py (contacts, what rests on what, reach and the groups it leaves apart), variants.py (one
sample of every variant), answers.py (what each variant does, over all samples and the standing
ones), ask.py (every variant with common random numbers, in one map or until decided), questions.py
(the questions built on ask). question.py: a question as an object, one class per kind
(the node's ``~/ask`` JSON read, answered, written back).
"""

from .answers import Alone, Answers, GivenStands, VariantAnswer
from .ask import VARIANTS_PER_TASK, ask, progress_dict
from .geometry import Contacts, contacts, dependents, groups, reach_m, resting_on
from .kinds import DEFAULT_SAFE_BELOW, DEFAULT_SUPPORT_THRESHOLD, Action, Place, Push, Region, Remove
from .questions import (PLACEMENT_GEOMETRY_S, ClearOrder, ClearStep, SupportGraph, best_place,
                        clear_order, place, place_at, placements_to_dict, push, question_spec, remove, resting_height_m,
                        support_graph)
from .question import (QUESTION_KINDS, QUESTIONS, ClearQuestion, PlaceQuestion, PushQuestion, Question, RemoveQuestion,
                       Reply, SupportQuestion, new_object_from_dict, question_from_dict)
from .variants import VariantTask, run_variants

__all__ = ["Action", "Alone", "Answers", "ClearOrder", "ClearQuestion", "ClearStep", "Contacts",
           "DEFAULT_SAFE_BELOW", "DEFAULT_SUPPORT_THRESHOLD", "GivenStands", "PLACEMENT_GEOMETRY_S", "Place",
           "PlaceQuestion", "Push", "PushQuestion", "QUESTIONS", "QUESTION_KINDS", "Question", "Region", "Remove",
           "RemoveQuestion", "Reply", "SupportGraph", "SupportQuestion", "VARIANTS_PER_TASK", "VariantAnswer",
           "VariantTask", "ask", "question_spec", "best_place", "clear_order", "contacts", "dependents", "groups",
           "new_object_from_dict", "place", "place_at", "placements_to_dict", "progress_dict", "push",
           "question_from_dict", "reach_m", "remove", "resting_height_m", "resting_on", "run_variants",
           "support_graph"]
