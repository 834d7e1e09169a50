"""Learning from the cell's history: springback per toolpath point from the local geometry.

- :mod:`roboisf.learn.features` — what a point's neighbourhood looks like (wall angle,
  curvature along and across the path, depth, distance to the rim, step-down, tool radius,
  sheet thickness, material);
- :mod:`roboisf.learn.springback` — a gradient-boosted regression of the normal springback on
  those features, validated by leaving whole parts out, with conformal intervals;
- :mod:`roboisf.learn.predict` — the predicted error map of a part not yet formed, per term.

Optional: needs scikit-learn (``pip install 'roboisf[history]'``). docs/history.md.
"""
