"""The control-room dashboard (``rls-uncertainty dashboard``; docs/dashboard.md): a local web
page that follows a running estimator node, or shows a finished replay, with each parameter's
estimate and its corrected and conventional 2-sigma bands (the paper's Figs. 6 and 13), the
convergence flags, the model fit and the health of the node's inputs.

Modules: :mod:`.model` (pairing arrays by stamp, bounded histories), :mod:`.health`
(``/diagnostics`` read back), :mod:`.hub` (state and page messages), :mod:`.settings` (node
name, discovery, reference values), :mod:`.server` (aiohttp), :mod:`.ros_source` (rclpy),
:mod:`.replay_source` (a replay's ``estimates.mcap``), :mod:`.app` (the command). The page is
``static/`` (HTML, CSS, JS written here) plus uPlot from the npm registry
(``scripts/setup_dashboard.sh``).
"""
