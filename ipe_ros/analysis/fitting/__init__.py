"""The IPE fitted to people (``ipe fit``): its free inputs chosen by the likelihood of people's
yes/no responses, cross-validated by stimulus.

``responses`` (people's shares per stimulus, checked), ``readout`` (which number of an answer is the
model's P(yes)), ``mapping`` (the model's probability to people's: a logistic with a lapse rate),
``grid`` (the model evaluated at every parameter value on common random numbers), ``crossval``
(folds, per-fold choice, held-out scores), ``fit`` (the whole fit and its parameter set),
``page`` (the Markdown/PNG report).
"""
