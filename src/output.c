/* output.c: what every file writer shares (output.h). */
#include "output.h"

#include <errno.h>
#include <string.h>

hr_status hr_file_close(FILE *fp, const char *path, int ok, int e, hr_err *err) {
  if (ok && fflush(fp) != 0) ok = 0, e = errno;
  if (ok && ferror(fp)) ok = 0, e = errno ? errno : EIO;
  if (fclose(fp) != 0 && ok) ok = 0, e = errno;
  if (ok) return HR_OK;
  remove(path);
  return hr_err_set(err, HR_ERR_IO, "%s: write failed: %s", path, strerror(e ? e : EIO));
}
