#!/usr/bin/env python3
"""usdchecker for usd-core from PyPI, which ships the pxr modules but not the
`usdchecker` script. Since USD 25.x `usdchecker` runs the UsdValidation
framework (UsdUtils.ComplianceChecker is gone from 26.x); this runs every
registered validator on the composed stage, as `usdchecker FILE` does, and
falls back to the ComplianceChecker on older releases.
Exit 1 on any error; warnings are printed."""
import sys

from pxr import Usd, UsdUtils


def main(paths):
    status = 0
    for path in paths:
        problems = []
        if hasattr(UsdUtils, "ComplianceChecker"):
            checker = UsdUtils.ComplianceChecker(arkit=False, skipARKitRootLayerCheck=False,
                                                 rootPackageOnly=False, skipVariants=False, verbose=False)
            checker.CheckCompliance(path)
            for w in checker.GetWarnings():
                print(f"{path}: warning: {w}")
            problems += list(checker.GetErrors()) + list(checker.GetFailedChecks())
        try:
            from pxr import UsdValidation
            registry = UsdValidation.ValidationRegistry()
            validators = registry.GetOrLoadAllValidators()
            ctx = UsdValidation.ValidationContext(validators)
            stage = Usd.Stage.Open(path)
            if stage is None:
                problems.append("cannot open the stage")
                raise ImportError
            for e in ctx.Validate(stage):
                line = f"{e.GetName()}: {e.GetMessage()}"
                if e.GetType() == UsdValidation.ValidationErrorType.Error:
                    problems.append(line)
                elif e.GetType() == UsdValidation.ValidationErrorType.Warn:
                    print(f"{path}: warning: {line}")
        except ImportError:
            pass
        for p in problems:
            print(f"{path}: ERROR: {p}")
        if problems:
            status = 1
        else:
            print(f"{path}: usdchecker: no errors")
    return status


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
