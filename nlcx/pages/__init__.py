"""One-page reports of nlcx's output directories: ``report.html`` and its Markdown twin.

``nlcx report DIR`` looks at what DIR holds — a reproduction (claims.csv and tables/), a
sweep (its tables sweep and metrics, as Parquet or CSV: :mod:`nlcx.pages.output_tables`) or
a run (manifest.json and metrics.csv) — and renders the page from Jinja2 templates
(nlcx/pages/templates/). The HTML is one self-contained file (its own CSS, charts as inline
SVG, figures linked relatively) that works offline from a file:// URL.
"""
