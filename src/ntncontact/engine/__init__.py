"""The step engine: model, builder, one step's problem, interfaces,
mesh motion, the time loop, diagnostics."""
