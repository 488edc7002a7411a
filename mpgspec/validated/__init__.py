"""Validated integration: rigorous enclosures of a closed loop's flow, for certified oracle verdicts.

The compiled closed loop is read back as its operation sequence (tape.py) and evaluated in arb
ball arithmetic (outward-rounded, python-flint): as balls for sound ranges, as truncated power
series for Taylor coefficients, as jets for their derivatives. flow.py steps a start box with a
Taylor method of chosen order, a Picard a-priori enclosure for the remainder and Lohner's QR
method against the wrapping effect; a step over which a law switches or kinks becomes a first-order
hull step. Verdicts it returns are proofs, not estimates.
"""
