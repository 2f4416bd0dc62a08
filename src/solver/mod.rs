//! Nonlinear solvers: Newton with line search, sparse KKT systems, quasi-static equilibrium.
