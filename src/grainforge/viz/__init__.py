"""Pictures: renders, plots, the paper's figures and the demo."""
