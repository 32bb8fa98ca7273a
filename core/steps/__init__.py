"""The method, one module per step, each a pure function on numpy arrays and ``Grid``s:
points → grid → slope → breakpoints → break lines → simplify → (localise) → PSLG → mesh →
refine → assess → export. ``floodmesh.core`` names the public ones; the chain that strings them
together over files is ``core.chain``."""
