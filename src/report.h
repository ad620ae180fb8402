/* report.h: machine-readable results (internal API). */
#ifndef HR_REPORT_H
#define HR_REPORT_H

#include "hrad.h"
#include <stdio.h>

/* surfaces.csv: header "id,area,r,g,b", one row per input polygon in input order. */
hr_status hr_report_csv(const char *path, const hr_solver *s, hr_err *err);
/* stats.json: counts, options, per-phase times (the paper's table columns) and rates. */
hr_status hr_report_json(const char *path, const hr_solver *s, const hr_options *o,
                         hr_err *err);
/* The paper's timing table (threads, init graph, refine, push-pull, sum) plus counts, as text. */
void hr_report_table(FILE *f, const hr_stats *st);

#endif
