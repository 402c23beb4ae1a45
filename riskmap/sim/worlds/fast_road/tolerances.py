"""The rounding margins the fast road's shortcuts keep: floats only decide what need not be
computed, always with a margin far beyond rounding."""

_TOL_M = 1e-6            # margin on distances compared against a bound (m, or m + rad)
_TOL_REL = 1e-12         # relative margin, for distances far beyond metres
