"""The paper's model analyses (Battaglia, Hamrick & Tenenbaum 2013, SI "Data Analysis", Table S2,
"Approximating Probabilities"), free of ROS like the engine.

    stats.py        Pearson and circular correlations with bootstrap medians and 95% intervals,
                    bootstrap hypothesis tests, the one-way ANOVA F ratio, the k estimator
    features.py     the geometric features of Table S2 (towers and Exp. 5 tables)
    ridge.py        cross-validated ridge regression from features to any target
    human.py        an optional human-response table (stimulus, response) -> per-stimulus summaries
    runs.py         the IPE run over a stimulus set: per-stimulus, per-sample query values
    experiments.py  one function per report (``ipe experiment NAME``)
    report.py       JSON + Markdown + PNG output
"""
