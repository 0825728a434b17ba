"""The margins under model error: the tasks on perturbed plants, their report, and the hold
against the size of the error by family."""
