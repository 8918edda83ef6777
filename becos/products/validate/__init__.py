"""Validation of a benchmark store (:mod:`becos.products.store`): every invariant a consumer relies on.

:func:`validate_store` returns human-readable problems (empty = valid); each starts with the name of
the check that failed, then says what is wrong, in how many pairs, with example pair ids (problems of
the whole store name the store, array or attribute). ``becos validate STORE [--threads N] [--json OUT] [--against
OTHER [--atol TOL]]`` exits 1 on problems or differing stores (:mod:`becos.products.compare`), 2 when OTHER
cannot be opened. Modules: ``run`` (the order of the checks), ``opening``, ``tables``, ``block``,
``content``, ``report``. The checks, one by one: docs/design/validate.md.
"""

from becos.products.validate.block import ROTATION_TOL, WEIGHT_TOL, BlockChecker
from becos.products.validate.opening import open_for_validation
from becos.products.validate.report import MAX_EXAMPLES, Problems, ValidationReport
from becos.products.validate.run import VALIDATE_BLOCK_BYTES, validate, validate_store
from becos.products.validate.tables import expected_schema

__all__ = [
    "MAX_EXAMPLES",
    "ROTATION_TOL",
    "VALIDATE_BLOCK_BYTES",
    "WEIGHT_TOL",
    "BlockChecker",
    "Problems",
    "ValidationReport",
    "expected_schema",
    "open_for_validation",
    "validate",
    "validate_store",
]
