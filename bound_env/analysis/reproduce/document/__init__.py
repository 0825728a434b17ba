"""The text of docs/REPRODUCTION.md: the numbers it derives from the stages' results, their
formatting, the table of every published number, and the page."""
