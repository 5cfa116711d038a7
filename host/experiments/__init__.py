"""The paper's experiments (the paper's section 5) run against a board or the virtual board, and the
Markdown report that puts each measured figure beside the paper's. See docs/paper-experiments.md."""
