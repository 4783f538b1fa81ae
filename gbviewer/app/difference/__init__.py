"""The difference and error views: what each pane compares and the thread that computes it."""
