"""pseudolight reports: metrics, ground-truth filtering, figures, HTML, regression, comparisons."""
