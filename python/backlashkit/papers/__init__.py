"""Reproductions of the source papers: each reruns a paper's protocol and prints its
numbers beside ours (``backlashkit reproduce PAPER``).

* :mod:`~backlashkit.papers.ravanbod2002` -- paper A, Ravanbod-Shirazi & Besançon-Voda,
  IFAC 2002: Tables 1 and 2, and the joint estimator against its Cramér-Rao bound;
* :mod:`~backlashkit.papers.tao1995` -- paper B, Tao & Kokotović, IEEE TAC 1995:
  the adaptive backlash inverse of Section IV, Figs. 5 and 6.
"""
