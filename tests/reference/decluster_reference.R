# Reference values for tests/stats/test_dependence_evt.py, from R evd (Debian r-cran-evd).
# Run from tests/data/evt:  Rscript ../../reference/decluster_reference.R
# Writes decluster_series.csv (the input series, x on a 1 s grid) and decluster_expected.csv
# (one row per threshold u and run length r: runs clusters of evd::clusters, their maxima and
# positions, and the extremal index of evd::exi by intervals (r = 0) and by runs (r > 0)).
library(evd)
set.seed(20031)
n <- 3000
a <- 0.6
z <- rfrechet(n)  # unit Frechet
x <- numeric(n)
x[1] <- z[1]
for (t in 2:n) x[t] <- max(a * x[t - 1], (1 - a) * z[t])  # ARMAX, extremal index 1 - a
write.csv(data.frame(x = sprintf("%.17g", x)), "decluster_series.csv", row.names = FALSE, quote = FALSE)
rows <- list()
for (u in c(2, 5, 10)) {
  for (r in c(1, 3, 10)) {
    cl <- clusters(x, u = u, r = r, cmax = TRUE, keep.names = TRUE)
    rows[[length(rows) + 1]] <- data.frame(
      u = u, r = r, n_clusters = length(cl),
      exi_intervals = sprintf("%.17g", exi(x, u = u, r = 0)),
      exi_runs = sprintf("%.17g", exi(x, u = u, r = r)),
      peak_index = paste(as.integer(names(cl)) - 1L, collapse = " "),  # 0-based
      peak_value = paste(sprintf("%.17g", as.numeric(cl)), collapse = " ")
    )
  }
}
write.csv(do.call(rbind, rows), "decluster_expected.csv", row.names = FALSE, quote = TRUE)
cat("R", R.version.string, "evd", as.character(packageVersion("evd")), "\n")
