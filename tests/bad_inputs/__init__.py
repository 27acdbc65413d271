"""End-to-end bad-input suite: every refusal asserts the exit status, one line of our own
text (no traceback), and that nothing is written outside the output folder or left half done."""
