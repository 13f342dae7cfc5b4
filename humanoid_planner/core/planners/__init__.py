"""Motion planners of the core: GIRRT and DAGRRT searches, the straight-line (Cartesian) moves and
the baseline planners, on the checkers and kinematics of a planning problem."""
