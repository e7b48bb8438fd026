"""CasADi trajectory optimisation and MPC for the next cycle's bucket path."""
