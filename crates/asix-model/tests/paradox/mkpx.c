/*
 * mkpx: writes Paradox tables with pxlib (Debian's pxlib-dev), an implementation of the
 * format independent of the reader in crates/asix-model/src/vardb/paradox.rs, so that
 * the reader is checked against files it did not write.
 *
 *   mkpx csv IN.csv OUT.DB CODEPAGE [COLUMN=TYPE ...]
 *       The CSV attribute table IN.csv (UTF-8, `;`-separated, RFC 4180 quotes) as a
 *       Paradox 7 table in code page CODEPAGE (1250 or 852; pxlib converts the text with
 *       iconv). Columns are alpha fields as wide as their longest cell unless named:
 *       TYPE is N (number), S (short), I (long), L (logical: tak/true/1, nie/false/0),
 *       or M<n> (memo with an n-byte head; the rest goes to OUT.MB). Empty cells are
 *       blank fields.
 *   mkpx types OUT.DB
 *       A table with a field of every type the reader decodes, and memos in OUT.MB.
 *
 * Built and run by crates/asix-model/tests/paradox.rs (cc mkpx.c -lpx).
 */
#include <iconv.h>
#include <paradox.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static void die(const char *m, const char *a) {
	fprintf(stderr, "mkpx: %s %s\n", m, a ? a : "");
	exit(1);
}

static void on_error(pxdoc_t *p, int type, const char *msg, void *data) {
	(void)p;
	(void)data;
	fprintf(stderr, "mkpx: pxlib: %s\n", msg);
	if (type != PX_Warning)
		exit(1);
}

/* ---- the CSV, read a row at a time (two passes at 1,000,000 rows need the text only) ---- */

static char *read_file(const char *path, long *len) {
	FILE *f = fopen(path, "rb");
	char *buf;
	if (!f)
		die("cannot open", path);
	fseek(f, 0, SEEK_END);
	*len = ftell(f);
	fseek(f, 0, SEEK_SET);
	buf = malloc(*len + 1);
	if (!buf || fread(buf, 1, *len, f) != (size_t)*len)
		die("cannot read", path);
	buf[*len] = 0;
	fclose(f);
	return buf;
}

struct row {
	char *buf;    /* the cells, each NUL-terminated */
	long *starts; /* cell k at buf + starts[k] */
	int n, cap;
};

/* Reads the row at text[*i] into `row` (blank lines skipped); 0 at the end. */
static int next_row(const char *text, long len, long *i, struct row *row) {
	long k;
	for (;;) {
		if (*i >= len)
			return 0;
		k = 0;
		row->n = 0;
		for (;;) {
			if (row->n == row->cap) {
				row->cap = row->cap ? row->cap * 2 : 32;
				row->starts = realloc(row->starts, row->cap * sizeof(long));
			}
			row->starts[row->n++] = k;
			if (*i < len && text[*i] == '"') {
				(*i)++;
				while (*i < len) {
					if (text[*i] == '"' && *i + 1 < len && text[*i + 1] == '"') {
						row->buf[k++] = '"';
						*i += 2;
					} else if (text[*i] == '"') {
						(*i)++;
						break;
					} else if (text[*i] == '\r' && *i + 1 < len && text[*i + 1] == '\n') {
						row->buf[k++] = '\n';
						*i += 2;
					} else {
						row->buf[k++] = text[(*i)++];
					}
				}
			} else {
				while (*i < len && text[*i] != ';' && text[*i] != '\r' && text[*i] != '\n')
					row->buf[k++] = text[(*i)++];
			}
			row->buf[k++] = 0;
			if (*i < len && text[*i] == ';') {
				(*i)++;
				continue;
			}
			if (*i < len && text[*i] == '\r')
				(*i)++;
			if (*i < len && text[*i] == '\n')
				(*i)++;
			break;
		}
		if (!(row->n == 1 && row->buf[0] == 0))
			return 1;
	}
}

static const char *cell_of(struct row *r, int c) {
	return c < r->n ? r->buf + r->starts[c] : "";
}

/* ---- writing ---- */

static pxdoc_t *create(const char *path, pxfield_t *fields, int n, int codepage) {
	pxdoc_t *px = PX_new2(on_error, NULL, NULL, NULL);
	char cp[16];
	if (!px || PX_create_file(px, fields, n, path, pxfFileTypNonIndexDB) < 0)
		die("cannot create", path);
	sprintf(cp, "CP%d", codepage);
	/* pxlib converts alpha values from the input encoding to the table's code page. */
	PX_set_parameter(px, "targetencoding", cp);
	PX_set_parameter(px, "inputencoding", "UTF-8");
	return px;
}

static void blob_file(pxdoc_t *px, const char *db) {
	char mb[4096];
	size_t n = strlen(db);
	if (n < 3 || n >= sizeof mb)
		die("bad table name", db);
	strcpy(mb, db);
	strcpy(mb + n - 2, "MB");
	if (PX_set_blob_file(px, mb) < 0)
		die("cannot create", mb);
}

/* UTF-8 text in the code page (pxlib converts alpha fields but not memos). */
static char *to_codepage(const char *utf8, int codepage) {
	char cp[16];
	size_t ilen = strlen(utf8), olen = ilen + 1;
	char *out = malloc(olen), *o = out, *i = (char *)utf8;
	iconv_t cd;
	sprintf(cp, "CP%d", codepage);
	cd = iconv_open(cp, "UTF-8");
	if (cd == (iconv_t)-1 || iconv(cd, &i, &ilen, &o, &olen) == (size_t)-1)
		die("cannot convert to the code page:", utf8);
	*o = 0;
	iconv_close(cd);
	return out;
}

static int codepage_of(pxdoc_t *px) {
	float v = 0;
	PX_get_value(px, "codepage", &v);
	return (int)v;
}

static int truthy(const char *s) {
	return !strcmp(s, "tak") || !strcmp(s, "true") || !strcmp(s, "1");
}

static void put(pxdoc_t *px, char *at, pxfield_t *f, const char *v) {
	if (!*v)
		return; /* blank: the record is zeroed */
	switch (f->px_ftype) {
	case pxfAlpha:
		PX_put_data_alpha(px, at, f->px_flen, (char *)v);
		break;
	case pxfNumber:
	case pxfCurrency:
		PX_put_data_double(px, at, 8, strtod(v, NULL));
		break;
	case pxfShort:
		PX_put_data_short(px, at, 2, (short)strtol(v, NULL, 10));
		break;
	case pxfLong:
	case pxfAutoInc:
		PX_put_data_long(px, at, 4, (int)strtol(v, NULL, 10));
		break;
	case pxfLogical:
		PX_put_data_byte(px, at, 1, truthy(v) ? 1 : 0);
		break;
	case pxfMemoBLOb: {
		char *text = to_codepage(v, codepage_of(px));
		if (PX_put_data_blob(px, at, f->px_flen, text, (int)strlen(text)) < 0)
			die("cannot write a memo", v);
		free(text);
		break;
	}
	default:
		die("unexpected field type", f->px_fname);
	}
}

static int csv_to_db(const char *in, const char *out, int codepage, char **specs, int nspecs) {
	long len, i, body;
	char *text = read_file(in, &len);
	struct row row = {0};
	int ncols, c, recsize = 0, memo = 0;
	row.buf = malloc(len + 1);
	i = len >= 3 && !memcmp(text, "\xEF\xBB\xBF", 3) ? 3 : 0;
	if (!next_row(text, len, &i, &row))
		die("no header in", in);
	body = i;
	ncols = row.n;
	pxfield_t *fields = calloc(ncols, sizeof(pxfield_t));
	for (c = 0; c < ncols; c++) {
		const char *name = cell_of(&row, c);
		int s, width = 1;
		fields[c].px_fname = strdup(name);
		fields[c].px_ftype = pxfAlpha;
		for (s = 0; s < nspecs; s++) {
			size_t n = strlen(name);
			if (!strncmp(specs[s], name, n) && specs[s][n] == '=') {
				const char *type = specs[s] + n + 1;
				switch (type[0]) {
				case 'N': fields[c].px_ftype = pxfNumber; width = 8; break;
				case 'S': fields[c].px_ftype = pxfShort; width = 2; break;
				case 'I': fields[c].px_ftype = pxfLong; width = 4; break;
				case 'L': fields[c].px_ftype = pxfLogical; width = 1; break;
				case 'M':
					fields[c].px_ftype = pxfMemoBLOb;
					width = atoi(type + 1) + 10;
					memo = 1;
					break;
				default: die("unknown type in", specs[s]);
				}
			}
		}
		fields[c].px_flen = width;
	}
	/* Pass 1: alpha fields as wide as their longest cell. */
	while (next_row(text, len, &i, &row)) {
		for (c = 0; c < ncols; c++) {
			int n = (int)strlen(cell_of(&row, c));
			if (fields[c].px_ftype == pxfAlpha && n > fields[c].px_flen) {
				if (n > 255)
					die("a cell longer than 255 bytes in column", fields[c].px_fname);
				fields[c].px_flen = n;
			}
		}
	}
	for (c = 0; c < ncols; c++)
		recsize += fields[c].px_flen;
	pxdoc_t *px = create(out, fields, ncols, codepage);
	if (memo)
		blob_file(px, out);
	char *rec = malloc(recsize);
	/* Pass 2: the records. */
	i = body;
	while (next_row(text, len, &i, &row)) {
		int at = 0;
		memset(rec, 0, recsize);
		for (c = 0; c < ncols; c++) {
			put(px, rec + at, &fields[c], cell_of(&row, c));
			at += fields[c].px_flen;
		}
		if (PX_put_record(px, rec) < 0)
			die("cannot write a record of", out);
	}
	PX_close(px);
	return 0;
}

/* Every field type the attribute table's reader decodes, with blank and negative values
 * and memos of every size (in the record, in a shared .MB block, in a block of its own). */
static int types_db(const char *out) {
	static pxfield_t f[] = {
		{"Name", pxfAlpha, 12, 0},
		{"Count", pxfShort, 2, 0},
		{"Total", pxfLong, 4, 0},
		{"Ratio", pxfNumber, 8, 0},
		{"Price", pxfCurrency, 8, 0},
		{"Flag", pxfLogical, 1, 0},
		{"Day", pxfDate, 4, 0},
		{"At", pxfTime, 4, 0},
		{"Stamp", pxfTimestamp, 8, 0},
		{"Serial", pxfAutoInc, 4, 0},
		{"Note", pxfMemoBLOb, 20, 0},
	};
	const int n = sizeof f / sizeof f[0];
	int i, recsize = 0;
	for (i = 0; i < n; i++) {
		f[i].px_fname = strdup(f[i].px_fname);
		recsize += f[i].px_flen;
	}
	pxdoc_t *px = create(out, f, n, 1250);
	blob_file(px, out);
	char *rec = malloc(recsize), *at;
	char *big = malloc(5000);
	for (i = 0; i < 4999; i++)
		big[i] = 'a' + i % 26;
	big[4999] = 0;
	for (i = 0; i < 3; i++) {
		pxval_t *d, *tm, *ts;
		memset(rec, 0, recsize);
		at = rec;
		if (i == 2) {
			/* Only the name: every other field blank. */
			PX_put_data_alpha(px, at, 12, "BLANK");
			PX_put_record(px, rec);
			break;
		}
		PX_put_data_alpha(px, at, 12, i == 0 ? "KW_ŻÓŁW" : "KW_minus");
		at += 12;
		PX_put_data_short(px, at, 2, i == 0 ? 32767 : -32767);
		at += 2;
		PX_put_data_long(px, at, 4, i == 0 ? 4000000 : -7);
		at += 4;
		PX_put_data_double(px, at, 8, i == 0 ? 0.5 : -1234.125);
		at += 8;
		PX_put_data_double(px, at, 8, i == 0 ? 12.99 : -0.01);
		at += 8;
		PX_put_data_byte(px, at, 1, i == 0 ? 1 : 0);
		at += 1;
		d = PX_make_date(px, i == 0 ? 2024 : 1999, i == 0 ? 2 : 12, i == 0 ? 29 : 31);
		PX_put_data_long(px, at, 4, (int)d->value.lval);
		at += 4;
		tm = PX_make_time(px, i == 0 ? 13 : 0, i == 0 ? 5 : 0, i == 0 ? 7 : 1);
		PX_put_data_long(px, at, 4, (int)tm->value.lval);
		at += 4;
		ts = PX_make_timestamp(px, 2001, 9, 11, 8, 46, 40);
		PX_put_data_double(px, at, 8, ts->value.dval);
		at += 8;
		PX_put_data_long(px, at, 4, i + 1);
		at += 4;
		if (i == 0) {
			/* Longer than the head: a slot of a shared .MB block. */
			char *note = to_codepage("Notatka dłuższa niż nagłówek pola,\r\nw pliku .MB", 1250);
			if (PX_put_data_blob(px, at, 20, note, (int)strlen(note)) < 0)
				die("memo", "1");
			free(note);
		} else {
			/* Over 2 KB: a .MB block of its own. */
			if (PX_put_data_blob(px, at, 20, big, 4999) < 0)
				die("memo", "2");
		}
		PX_put_record(px, rec);
	}
	/* A memo short enough for the record's head. */
	memset(rec, 0, recsize);
	PX_put_data_alpha(px, rec, 12, "SHORT");
	char *short_note = to_codepage("krótka", 1250);
	PX_put_data_blob(px, rec + recsize - 20, 20, short_note, (int)strlen(short_note));
	PX_put_record(px, rec);
	PX_close(px);
	return 0;
}

int main(int argc, char **argv) {
	PX_boot();
	if (argc >= 5 && !strcmp(argv[1], "csv"))
		return csv_to_db(argv[2], argv[3], atoi(argv[4]), argv + 5, argc - 5);
	if (argc == 3 && !strcmp(argv[1], "types"))
		return types_db(argv[2]);
	fprintf(stderr, "usage: mkpx csv IN.csv OUT.DB CODEPAGE [COLUMN=TYPE ...] | mkpx types OUT.DB\n");
	return 2;
}
