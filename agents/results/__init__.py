"""The results page: the margins commands, the passive-vs-learned tables of ``docs/MARGINS.md``
and the numbers, prose and demo built from them."""
