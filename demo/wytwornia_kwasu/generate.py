#!/usr/bin/env python3
"""Generates the demo variable database of the acid plant Wytwornia_Kwasu.

Writes, next to this script:
  atrybuty.csv          the attribute table (UTF-8 with BOM, `;` separator)
  wytwornia_kwasu.zez   the variable set (browse tree) naming the table

Format: docs/variable-database.md. The output is deterministic; the files are
committed, rerun this script after editing it:  python3 demo/wytwornia_kwasu/generate.py

Naming (asix style, as KW_A000 / KW_A110 of the original manual):
  KW_Annn  analogue values (measurements R4, setpoints writable)
  KW_Dnnn  discrete states and counters (I2 / UI2 / UI4 / UI1)
  KW_Knnn  control variables of the PLC links (0 = healthy, nonzero = failure)
  KW_Lnnn  limit variables used as indirect limits (writable)
  hundreds digit = plant section: 0 sulphur store, 1 burning, 2 converter,
  3 absorption, 4 acid store & shipping, 5 utilities.
Column Alias holds ISA-style tags (LI101, TIC201, ...); control and limit variables
have no alias and are hidden when AliasAttributeName = Alias.
"""
import csv
import os

COLUMNS = [
    "Name", "Alias", "Description", "DescriptionEn", "Unit", "RangeFrom", "RangeTo",
    "DataType", "Format", "WarnLow", "WarnHigh", "AlarmLow", "AlarmHigh",
    "ControlVariable", "BarBase", "Writable", "Channel", "Address", "SampleRate",
]

# Asix channel (Asmen) and PLC control variable of each section.
SECTIONS = {
    0: ("SIARKA", "KW_K001", 10),
    1: ("PIEC", "KW_K002", 20),
    2: ("KONTAKT", "KW_K003", 30),
    3: ("ABSORPCJA", "KW_K004", 40),
    4: ("MAGAZYN", "KW_K005", 50),
    5: ("MEDIA", "KW_K006", 60),
}

rows = []          # attribute rows (dicts)
groups = {}        # group path -> [names]
group_order = []
offsets = {}       # section -> next byte offset in its data block


def fmtnum(x):
    if x is None:
        return ""
    if isinstance(x, str):
        return x
    if float(x).is_integer():
        return str(int(x))
    return repr(float(x))


def add(group, name, alias, pl, en, unit="", lo=None, hi=None, fmt="%.1f", limits=(None, None, None, None),
        dtype="R4", writable=False, barbase=None, control=True, sample=1):
    section = int(name[4]) if name[3] in "AD" else None
    if section is not None:
        channel, ctl, db = SECTIONS[section]
    else:
        channel, ctl, db = ("DIAGNOSTYKA", "", 90)
        section = 9
    off = offsets.get(section, 0)
    size = 4 if dtype in ("R4", "I4", "UI4") else 2
    offsets[section] = off + size
    wl, wh, al, ah = limits
    rows.append({
        "Name": name,
        "Alias": alias,
        "Description": pl,
        "DescriptionEn": en[:1].upper() + en[1:],
        "Unit": unit,
        "RangeFrom": fmtnum(lo),
        "RangeTo": fmtnum(hi),
        "DataType": dtype,
        "Format": fmt,
        "WarnLow": fmtnum(wl),
        "WarnHigh": fmtnum(wh),
        "AlarmLow": fmtnum(al),
        "AlarmHigh": fmtnum(ah),
        "ControlVariable": ctl if control else "",
        "BarBase": fmtnum(barbase),
        "Writable": "tak" if writable else "nie",
        "Channel": channel,
        "Address": f"DB{db}.DB{'D' if size == 4 else 'W'}{off}",
        "SampleRate": str(sample),
    })
    if group not in groups:
        groups[group] = []
        group_order.append(group)
    groups[group].append(name)


def state(group, name, alias, pl, en):
    add(group, name, alias, pl, en, "", 0, 1, "%d", dtype="I2")


# ---------------------------------------------------------------- 0: sulphur store
G = "Magazyn siarki"
for i, (tank, n0) in enumerate((("Z101", 0), ("Z102", 3))):
    g = f"{G}/Zbiornik siarki ciekłej {tank}"
    t = tank[1:]
    add(g, f"KW_A{n0:03}", f"LI{t}", f"Poziom siarki ciekłej w zbiorniku {tank}",
        f"Liquid sulphur level in tank {tank}", "m", 0, 8, "%.2f", (1.0, 7.0, 0.5, 7.5))
    add(g, f"KW_A{n0+1:03}", f"TI{t}", f"Temperatura siarki w zbiorniku {tank}",
        f"Sulphur temperature in tank {tank}", "°C", 100, 180, "%.1f", (125, 150, 120, 155))
    add(g, f"KW_A{n0+2:03}", f"PI{t}", f"Ciśnienie pary grzewczej wężownicy {tank}",
        f"Heating coil steam pressure {tank}", "bar", 0, 10, "%.2f", (3.0, 7.0, 2.0, 8.0))
g = f"{G}/Topielnik siarki T103"
add(g, "KW_A006", "LI103", "Poziom w topielniku T103", "Melter T103 level", "%", 0, 100, "%.0f", (20, 85, 10, 95))
add(g, "KW_A007", "TI103", "Temperatura siarki w topielniku T103", "Sulphur temperature in melter T103", "°C", 100, 180, "%.1f", (128, 152, 122, 158))
add(g, "KW_A008", "FI103", "Przepływ pary do topielnika T103", "Steam flow to melter T103", "t/h", 0, 6, "%.2f", (None, 5.0, None, 5.6))
add(g, "KW_A009", "WI103", "Dozowanie siarki stałej do topielnika", "Solid sulphur feed to the melter", "t/h", 0, 25, "%.1f")
add(g, "KW_A010", "WIC103", "Zadane dozowanie siarki stałej", "Solid sulphur feed setpoint", "t/h", 0, 25, "%.1f", writable=True)
state(g, "KW_D000", "MS103", "Mieszadło topielnika T103 - praca", "Melter T103 agitator running")
add(g, "KW_A011", "II103", "Prąd silnika mieszadła T103", "Melter T103 agitator motor current", "A", 0, 60, "%.1f", (None, 45, None, 55))
g = f"{G}/Filtr siarki F104"
add(g, "KW_A012", "PDI104", "Spadek ciśnienia na filtrze siarki F104", "Sulphur filter F104 pressure drop", "kPa", 0, 300, "%.0f", (None, 180, None, 250))
add(g, "KW_A013", "TI104", "Temperatura siarki za filtrem F104", "Sulphur temperature after filter F104", "°C", 100, 180, "%.1f", (128, 152, 122, 158))
state(g, "KW_D001", "XS104", "Filtr F104 - w pracy (0 = płukanie)", "Filter F104 in service (0 = backwash)")
for j, p in enumerate(("P105A", "P105B")):
    g = f"{G}/Pompa siarki {p}"
    state(g, f"KW_D{2+j:03}", f"MS{p[1:]}", f"Pompa siarki {p} - praca", f"Sulphur pump {p} running")
    add(g, f"KW_A{14+3*j:03}", f"II{p[1:]}", f"Prąd silnika pompy {p}", f"Pump {p} motor current", "A", 0, 40, "%.1f", (None, 30, None, 36))
    add(g, f"KW_A{15+3*j:03}", f"PI{p[1:]}", f"Ciśnienie tłoczenia pompy {p}", f"Pump {p} discharge pressure", "bar", 0, 16, "%.2f", (4, 12, 2, 14))
    add(g, f"KW_A{16+3*j:03}", f"SI{p[1:]}", f"Prędkość obrotowa pompy {p}", f"Pump {p} speed", "obr/min", 0, 3000, "%.0f", dtype="UI2")
g = f"{G}/Rurociąg siarki do pieca"
add(g, "KW_A020", "FI106", "Przepływ siarki ciekłej do pieca", "Liquid sulphur flow to the furnace", "t/h", 0, 20, "%.2f", (4, 16, 2, 18))
add(g, "KW_A021", "TI106", "Temperatura rurociągu siarki (płaszcz parowy)", "Sulphur line (steam jacket) temperature", "°C", 100, 180, "%.1f", (130, 155, 125, 160))
add(g, "KW_D004", "FQ106", "Licznik siarki podanej do pieca", "Sulphur fed to the furnace, totaliser", "t", 0, 4000000000, "%u", dtype="UI4", control=True, sample=5)

# ---------------------------------------------------------------- 1: sulphur burning
G = "Spalanie siarki"
g = f"{G}/Piec siarkowy P201"
add(g, "KW_A100", "TI201", "Temperatura w strefie palników pieca P201", "Furnace P201 burner zone temperature", "°C", 0, 1200, "%.0f", (900, "KW_L001", 850, "KW_L002"))
add(g, "KW_A101", "TI202", "Temperatura gazu na wylocie z pieca", "Furnace outlet gas temperature", "°C", 0, 1200, "%.0f", (880, 1060, 820, 1100))
add(g, "KW_A102", "AI201", "Stężenie SO2 w gazie z pieca", "SO2 concentration in furnace gas", "%", 0, 15, "%.2f", (9.5, 12.0, 8.0, "KW_L004"))
add(g, "KW_A103", "AI202", "Zawartość tlenu w gazie z pieca", "Oxygen in furnace gas", "%", 0, 21, "%.2f", (8.0, 12.0, 7.0, 13.0))
add(g, "KW_A104", "PI201", "Ciśnienie w komorze pieca", "Furnace chamber pressure", "kPa", -5, 15, "%.2f", (None, 10, None, 12), barbase=0)
for k in range(2):
    add(g, f"KW_A{105+k}", f"PI20{2+k}", f"Ciśnienie siarki przed dyszą nr {k+1}", f"Sulphur pressure before nozzle {k+1}", "bar", 0, 25, "%.1f", (8, 20, 6, 22))
    state(g, f"KW_D{100+k}", f"BS20{1+k}", f"Czujnik płomienia palnika nr {k+1}", f"Burner {k+1} flame detector")
add(g, "KW_A107", "TI203", "Temperatura płaszcza pieca", "Furnace shell temperature", "°C", 0, 400, "%.0f", (None, 250, None, 320))
g = f"{G}/Nastawy"
add(g, "KW_A110", "FIC110", "Zadana wydajność siarki do pieca", "Sulphur feed rate setpoint", "t/h", 0, 20, "%.2f", writable=True)
add(g, "KW_A111", "FIC111", "Zadany przepływ powietrza do pieca", "Combustion air flow setpoint", "kNm3/h", 0, 120, "%.1f", writable=True)
add(g, "KW_A112", "AIC112", "Zadane stężenie SO2 w gazie z pieca", "SO2 concentration setpoint", "%", 0, 15, "%.2f", writable=True)
g = f"{G}/Dmuchawa powietrza D202"
state(g, "KW_D102", "MS202", "Dmuchawa powietrza D202 - praca", "Air blower D202 running")
add(g, "KW_A113", "SI202", "Prędkość obrotowa dmuchawy D202", "Blower D202 speed", "obr/min", 0, 6000, "%.0f", (None, 5200, None, 5600), dtype="UI2")
add(g, "KW_A114", "II202", "Prąd silnika dmuchawy D202", "Blower D202 motor current", "A", 0, 400, "%.0f", (None, 330, None, 370))
add(g, "KW_A115", "FI202", "Przepływ powietrza do pieca", "Combustion air flow", "kNm3/h", 0, 120, "%.1f", (40, 110, 30, 115))
add(g, "KW_A116", "PI204", "Ciśnienie tłoczenia dmuchawy D202", "Blower D202 discharge pressure", "kPa", 0, 60, "%.1f", (20, 50, 15, 55))
add(g, "KW_A117", "TI204", "Temperatura łożyska dmuchawy - strona napędu", "Blower bearing temperature, drive end", "°C", 0, 120, "%.0f", (None, 80, None, 95))
add(g, "KW_A118", "TI205", "Temperatura łożyska dmuchawy - strona wolna", "Blower bearing temperature, free end", "°C", 0, 120, "%.0f", (None, 80, None, 95))
add(g, "KW_A119", "VI202", "Drgania dmuchawy D202", "Blower D202 vibration", "mm/s", 0, 20, "%.1f", (None, 7.1, None, 11.0))
add(g, "KW_A120", "ZI202", "Położenie kierownicy dmuchawy D202", "Blower D202 inlet guide vane position", "%", 0, 100, "%.0f")
g = f"{G}/Kocioł odzysknicowy K203"
add(g, "KW_A121", "LI203", "Poziom wody w walczaku kotła K203", "Boiler K203 drum level", "mm", -200, 200, "%+.0f", (-80, 80, "KW_L003", 150), barbase=0)
add(g, "KW_A122", "PI206", "Ciśnienie pary w walczaku K203", "Boiler K203 drum pressure", "bar", 0, 60, "%.1f", (35, 45, 30, 48))
add(g, "KW_A123", "TI206", "Temperatura pary przegrzanej z kotła K203", "Boiler K203 superheated steam temperature", "°C", 0, 500, "%.0f", (380, 430, 360, 450))
add(g, "KW_A124", "FI206", "Przepływ pary z kotła K203", "Boiler K203 steam flow", "t/h", 0, 60, "%.1f", (None, 52, None, 56))
add(g, "KW_A125", "FI207", "Przepływ wody zasilającej kocioł K203", "Boiler K203 feed water flow", "t/h", 0, 60, "%.1f")
add(g, "KW_A126", "TI207", "Temperatura wody zasilającej", "Feed water temperature", "°C", 0, 200, "%.0f", (95, 140, 90, 150))
add(g, "KW_A127", "TI208", "Temperatura gazu za kotłem K203", "Gas temperature after boiler K203", "°C", 0, 600, "%.0f", (400, 440, 390, 460))
add(g, "KW_A128", "AI207", "Przewodność wody kotłowej", "Boiler water conductivity", "µS/cm", 0, 200, "%.0f", (None, 100, None, 150))
add(g, "KW_A129", "ZI208", "Otwarcie zaworu odmulania kotła", "Boiler blowdown valve opening", "%", 0, 100, "%.0f")
g = f"{G}/Filtr gorącego gazu F204"
add(g, "KW_A130", "PDI204", "Spadek ciśnienia na filtrze gorącego gazu", "Hot gas filter pressure drop", "kPa", 0, 5, "%.2f", (None, 2.5, None, 3.5))
add(g, "KW_A131", "TI209", "Temperatura gazu za filtrem F204", "Gas temperature after filter F204", "°C", 0, 600, "%.0f", (400, 440, 390, 460))

# ---------------------------------------------------------------- 2: converter
G = "Węzeł kontaktowy"
bed_in = [(415, 440), (430, 460), (425, 450), (410, 435)]
bed_out = [(590, 625), (500, 530), (450, 475), (420, 440)]
for k in range(4):
    g = f"{G}/Konwertor C210/Półka {k+1}"
    n = 200 + 4 * k
    lo, hi = bed_in[k]
    add(g, f"KW_A{n}", f"TI21{k}A", f"Temperatura gazu na wlocie do półki {k+1}", f"Bed {k+1} inlet gas temperature", "°C", 300, 700, "%.1f", (lo, hi, lo - 10, hi + 10))
    lo, hi = bed_out[k]
    add(g, f"KW_A{n+1}", f"TI21{k}B", f"Temperatura gazu na wylocie z półki {k+1}", f"Bed {k+1} outlet gas temperature", "°C", 300, 700, "%.1f", (lo, hi, lo - 15, hi + 15))
    add(g, f"KW_A{n+2}", f"PDI21{k}", f"Spadek ciśnienia na półce {k+1}", f"Bed {k+1} pressure drop", "kPa", 0, 10, "%.2f", (None, 4.0, None, 6.0))
    add(g, f"KW_A{n+3}", f"TI21{k}C", f"Temperatura katalizatora - półka {k+1}, środek warstwy", f"Bed {k+1} mid-layer catalyst temperature", "°C", 300, 700, "%.1f")
g = f"{G}/Konwertor C210"
add(g, "KW_A216", "AI210", "Stężenie SO2 na wlocie do konwertora", "SO2 at converter inlet", "%", 0, 15, "%.2f", (9.5, 12.0, 8.0, 12.5))
add(g, "KW_A217", "AI211", "Stopień konwersji SO2 (wyliczany)", "SO2 conversion (calculated)", "%", 90, 100, "%.2f", (99.6, None, 99.3, None))
add(g, "KW_A218", "PI210", "Ciśnienie gazu na wlocie do konwertora", "Converter inlet gas pressure", "kPa", 0, 60, "%.1f")
add(g, "KW_A219", "PI211", "Ciśnienie gazu na wylocie z konwertora", "Converter outlet gas pressure", "kPa", 0, 60, "%.1f")
for k, (w, pl_desc, en_desc) in enumerate((
        ("W221", "Wymiennik gorący W221", "hot heat exchanger W221"),
        ("W222", "Wymiennik pośredni W222", "intermediate heat exchanger W222"),
        ("W223", "Wymiennik zimny W223", "cold heat exchanger W223"),
        ("W224", "Ekonomizer W224", "economiser W224"))):
    g = f"{G}/Wymienniki ciepła/{pl_desc}"
    n = 220 + 4 * k
    add(g, f"KW_A{n}", f"TI{w[1:]}A", f"{pl_desc} - temperatura gazu wlot", f"{en_desc} gas inlet temperature", "°C", 0, 700, "%.0f")
    add(g, f"KW_A{n+1}", f"TI{w[1:]}B", f"{pl_desc} - temperatura gazu wylot", f"{en_desc} gas outlet temperature", "°C", 0, 700, "%.0f")
    add(g, f"KW_A{n+2}", f"ZI{w[1:]}", f"{pl_desc} - otwarcie obejścia", f"{en_desc} bypass valve position", "%", 0, 100, "%.0f")
    add(g, f"KW_A{n+3}", f"ZIC{w[1:]}", f"{pl_desc} - zadane otwarcie obejścia", f"{en_desc} bypass valve setpoint", "%", 0, 100, "%.0f", writable=True)
g = f"{G}/Podgrzewacz rozruchowy H230"
state(g, "KW_D200", "BS230", "Palnik podgrzewacza rozruchowego - płomień", "Start-up heater burner flame")
add(g, "KW_A236", "TI230", "Temperatura gazu za podgrzewaczem H230", "Gas temperature after start-up heater H230", "°C", 0, 700, "%.0f", (None, 480, None, 520))
add(g, "KW_A237", "FI230", "Przepływ gazu ziemnego do palnika H230", "Natural gas flow to heater H230", "Nm3/h", 0, 800, "%.0f")
add(g, "KW_D201", "", "Tryb pracy podgrzewacza (0 wył., 1 ręczny, 2 auto)", "Heater mode (0 off, 1 manual, 2 auto)", "", 0, 2, "%d", dtype="UI1", writable=True)

# ---------------------------------------------------------------- 3: absorption and drying
G = "Absorpcja i suszenie"
towers = [
    ("WS301", "Wieża suszenia WS301", "drying tower WS301", 300, (95.5, 96.5, 95.0, 97.0), (45, 60, 40, 65)),
    ("A302", "Absorber pośredni A302", "intermediate absorber A302", 306, (98.3, 98.8, 98.0, 99.0), (70, 85, 65, 90)),
    ("A303", "Absorber końcowy A303", "final absorber A303", 312, (98.3, 98.8, 98.0, 99.0), (65, 80, 60, 85)),
]
for tag, pl_name, en_name, n, conc_l, temp_l in towers:
    g = f"{G}/{pl_name}"
    t = tag[-3:]
    add(g, f"KW_A{n}", f"AI{t}", f"{pl_name} - stężenie kwasu zraszającego", f"{en_name} irrigating acid concentration", "% H2SO4", 90, 100, "%.2f", conc_l)
    add(g, f"KW_A{n+1}", f"TI{t}A", f"{pl_name} - temperatura kwasu na wlocie", f"{en_name} acid inlet temperature", "°C", 0, 120, "%.1f", temp_l)
    add(g, f"KW_A{n+2}", f"TI{t}B", f"{pl_name} - temperatura kwasu na wylocie", f"{en_name} acid outlet temperature", "°C", 0, 150, "%.1f")
    add(g, f"KW_A{n+3}", f"FI{t}", f"{pl_name} - przepływ kwasu zraszającego", f"{en_name} acid circulation flow", "m3/h", 0, 800, "%.0f", (300, None, 250, None))
    add(g, f"KW_A{n+4}", f"PDI{t}", f"{pl_name} - spadek ciśnienia na wypełnieniu", f"{en_name} packing pressure drop", "kPa", 0, 5, "%.2f", (None, 2.0, None, 3.0))
    add(g, f"KW_A{n+5}", f"AIC{t}", f"{pl_name} - zadane stężenie kwasu", f"{en_name} acid concentration setpoint", "% H2SO4", 90, 100, "%.2f", writable=True)
for k, (tank, pl_owner) in enumerate((("Z304", "wieży suszenia"), ("Z305", "absorbera pośredniego"), ("Z306", "absorbera końcowego"))):
    g = f"{G}/Zbiorniki cyrkulacyjne/Zbiornik {tank}"
    n = 318 + 2 * k
    add(g, f"KW_A{n}", f"LI{tank[1:]}", f"Poziom w zbiorniku cyrkulacyjnym {pl_owner} {tank}", f"Circulation tank {tank} level", "%", 0, 100, "%.0f", (30, 80, 20, 90))
    add(g, f"KW_A{n+1}", f"TI{tank[1:]}", f"Temperatura kwasu w zbiorniku {tank}", f"Acid temperature in tank {tank}", "°C", 0, 150, "%.1f")
for k, pump in enumerate(("P307A", "P307B", "P308A", "P308B", "P309A", "P309B")):
    g = f"{G}/Pompy kwasu/Pompa {pump}"
    state(g, f"KW_D{300+k}", f"MS{pump[1:]}", f"Pompa kwasu {pump} - praca", f"Acid pump {pump} running")
    add(g, f"KW_A{324+k}", f"II{pump[1:]}", f"Prąd silnika pompy kwasu {pump}", f"Acid pump {pump} motor current", "A", 0, 150, "%.0f", (None, 120, None, 135))
for k, (c, pl_owner) in enumerate((("CH310", "wieży suszenia"), ("CH311", "absorbera pośredniego"), ("CH312", "absorbera końcowego"))):
    g = f"{G}/Chłodnice kwasu/Chłodnica {c}"
    n = 330 + 3 * k
    add(g, f"KW_A{n}", f"TI{c[2:]}A", f"Chłodnica {c} ({pl_owner}) - woda wlot", f"Acid cooler {c} cooling water inlet", "°C", 0, 60, "%.1f", (None, 32, None, 35))
    add(g, f"KW_A{n+1}", f"TI{c[2:]}B", f"Chłodnica {c} ({pl_owner}) - woda wylot", f"Acid cooler {c} cooling water outlet", "°C", 0, 60, "%.1f", (None, 45, None, 50))
    add(g, f"KW_A{n+2}", f"AI{c[2:]}", f"Chłodnica {c} - pH wody (detekcja przecieku)", f"Acid cooler {c} water pH (leak detection)", "pH", 0, 14, "%.2f", (6.0, None, 5.0, None))
g = f"{G}/Rozcieńczanie"
add(g, "KW_A339", "FI339", "Przepływ wody rozcieńczającej", "Dilution water flow", "m3/h", 0, 20, "%.2f")
add(g, "KW_A340", "FIC339", "Zadany przepływ wody rozcieńczającej", "Dilution water flow setpoint", "m3/h", 0, 20, "%.2f", writable=True)
add(g, "KW_A341", "FI341", "Przepływ kwasu produkcyjnego do magazynu", "Product acid flow to storage", "t/h", 0, 60, "%.1f")
g = f"{G}/Emisja - komin E313"
add(g, "KW_A342", "AI342", "Emisja SO2 do atmosfery", "SO2 emission to atmosphere", "mg/Nm3", 0, 2000, "%.0f", (None, "KW_L005", None, "KW_L006"))
add(g, "KW_A343", "AI343", "Emisja mgły SO3/H2SO4", "SO3/H2SO4 mist emission", "mg/Nm3", 0, 200, "%.0f", (None, 50, None, 80))
add(g, "KW_A344", "FI344", "Przepływ gazów odlotowych", "Tail gas flow", "kNm3/h", 0, 150, "%.1f")
add(g, "KW_A345", "TI344", "Temperatura gazów odlotowych", "Tail gas temperature", "°C", 0, 150, "%.0f")
add(g, "KW_A346", "AI346", "Zawartość tlenu w gazach odlotowych", "Oxygen in tail gas", "%", 0, 21, "%.2f")
add(g, "KW_A347", "", "Emisja SO2 - średnia 30-minutowa", "SO2 emission, 30-minute average", "mg/Nm3", 0, 2000, "%.0f", (None, "KW_L005", None, "KW_L006"), sample=60)

# ---------------------------------------------------------------- 4: acid store and shipping
G = "Magazyn kwasu i ekspedycja"
for k in range(4):
    tank = f"Z40{k+1}"
    g = f"{G}/Zbiorniki kwasu/Zbiornik {tank}"
    n = 400 + 4 * k
    add(g, f"KW_A{n}", f"LI{tank[1:]}", f"Poziom kwasu w zbiorniku magazynowym {tank}", f"Acid level in storage tank {tank}", "m", 0, 12, "%.2f", (0.8, 10.5, 0.4, 11.2))
    add(g, f"KW_A{n+1}", f"VI{tank[1:]}", f"Zapas kwasu w zbiorniku {tank}", f"Acid inventory in tank {tank}", "t", 0, 2500, "%.0f")
    add(g, f"KW_A{n+2}", f"TI{tank[1:]}", f"Temperatura kwasu w zbiorniku {tank}", f"Acid temperature in tank {tank}", "°C", 0, 80, "%.1f", (None, 45, None, 55))
    add(g, f"KW_A{n+3}", f"AI{tank[1:]}", f"Stężenie kwasu w zbiorniku {tank}", f"Acid concentration in tank {tank}", "% H2SO4", 90, 100, "%.2f", (98.0, None, 97.5, None))
for k, pump in enumerate(("P405", "P406")):
    g = f"{G}/Pompy ekspedycyjne/Pompa {pump}"
    state(g, f"KW_D{400+k}", f"MS{pump[1:]}", f"Pompa ekspedycyjna {pump} - praca", f"Shipping pump {pump} running")
    add(g, f"KW_A{416+2*k}", f"II{pump[1:]}", f"Prąd silnika pompy {pump}", f"Pump {pump} motor current", "A", 0, 80, "%.1f", (None, 60, None, 70))
    add(g, f"KW_A{417+2*k}", f"FI{pump[1:]}", f"Wydajność pompy {pump}", f"Pump {pump} flow", "m3/h", 0, 150, "%.1f")
g = f"{G}/Nalewak cystern N410"
add(g, "KW_A420", "FI410", "Przepływ kwasu do cysterny", "Acid flow to the tank car", "t/h", 0, 200, "%.1f")
add(g, "KW_A421", "WI410", "Masa na wadze wagonowej", "Weight on the rail scale", "t", 0, 100, "%.2f", (None, 62, None, 66))
add(g, "KW_A422", "WIC410", "Zadana masa nalewu", "Filling batch setpoint", "t", 0, 70, "%.1f", writable=True)
add(g, "KW_D402", "FQ410", "Licznik kwasu wydanego", "Acid shipped, totaliser", "t", 0, 4000000000, "%u", dtype="UI4", sample=5)
state(g, "KW_D403", "ZS410", "Zawór nalewu otwarty", "Filling valve open")
state(g, "KW_D404", "XS410", "Uziemienie cysterny prawidłowe", "Tank car earthing OK")
add(g, "KW_D405", "", "Liczba cystern nalanych w bieżącej zmianie", "Tank cars filled this shift", "szt.", 0, 100, "%d", dtype="UI2")
g = f"{G}/Tace ochronne"
state(g, "KW_D406", "LS411", "Wyciek w tacy zbiorników Z401-Z402", "Leak in bund of tanks Z401-Z402")
state(g, "KW_D407", "LS412", "Wyciek w tacy zbiorników Z403-Z404", "Leak in bund of tanks Z403-Z404")
add(g, "KW_A423", "AI411", "pH w studzience tacy ochronnej", "Bund sump pH", "pH", 0, 14, "%.1f", (6.0, 9.0, 4.0, 10.0))

# ---------------------------------------------------------------- 5: utilities
G = "Media"
g = f"{G}/Woda chłodząca"
add(g, "KW_A500", "TI500", "Temperatura wody chłodzącej - zasilanie", "Cooling water supply temperature", "°C", 0, 50, "%.1f", (None, 28, None, 32))
add(g, "KW_A501", "TI501", "Temperatura wody chłodzącej - powrót", "Cooling water return temperature", "°C", 0, 60, "%.1f", (None, 40, None, 45))
add(g, "KW_A502", "FI500", "Przepływ wody chłodzącej", "Cooling water flow", "m3/h", 0, 3000, "%.0f", (1200, None, 1000, None))
add(g, "KW_A503", "PI500", "Ciśnienie wody chłodzącej", "Cooling water pressure", "bar", 0, 8, "%.2f", (2.5, 5.5, 2.0, 6.0))
for k, pump in enumerate(("P501A", "P501B", "P501C")):
    state(g, f"KW_D{500+k}", f"MS{pump[1:]}", f"Pompa wody chłodzącej {pump} - praca", f"Cooling water pump {pump} running")
add(g, "KW_A504", "TI504", "Temperatura na wylocie z chłodni wentylatorowej", "Cooling tower outlet temperature", "°C", 0, 50, "%.1f")
state(g, "KW_D503", "MS504", "Wentylator chłodni - praca", "Cooling tower fan running")
g = f"{G}/Woda zdemineralizowana"
add(g, "KW_A505", "LI505", "Poziom w zbiorniku wody zdemineralizowanej", "Demineralised water tank level", "%", 0, 100, "%.0f", (25, None, 10, None))
add(g, "KW_A506", "AI505", "Przewodność wody zdemineralizowanej", "Demineralised water conductivity", "µS/cm", 0, 20, "%.2f", (None, 0.5, None, 1.0))
add(g, "KW_A507", "FI505", "Przepływ wody zdemineralizowanej", "Demineralised water flow", "m3/h", 0, 80, "%.1f")
g = f"{G}/Para i turbozespół"
add(g, "KW_A508", "PI508", "Ciśnienie pary; kolektor wysokoprężny", "HP steam header pressure", "bar", 0, 60, "%.1f", (35, 45, 30, 48))
add(g, "KW_A509", "TI508", "Temperatura pary w kolektorze wysokoprężnym", "HP steam header temperature", "°C", 0, 500, "%.0f")
add(g, "KW_A510", "PI510", "Ciśnienie pary niskoprężnej", "LP steam pressure", "bar", 0, 10, "%.2f", (3.0, 5.5, 2.5, 6.0))
add(g, "KW_A511", "FI511", "Eksport pary do sieci zakładowej", "Steam export to the site network", "t/h", 0, 40, "%.1f")
add(g, "KW_A512", "JI512", "Moc czynna turbogeneratora TG1", "Turbine generator TG1 active power", "kW", 0, 12000, "%.0f", (None, 10500, None, 11500))
add(g, "KW_A513", "SI512", "Prędkość obrotowa turbiny TG1", "Turbine TG1 speed", "obr/min", 0, 12000, "%.0f", (None, 10300, None, 10800), dtype="UI2")
state(g, "KW_D504", "XS512", "Turbogenerator TG1 zsynchronizowany z siecią", "Turbine generator TG1 synchronised")
g = f"{G}/Sprężone powietrze"
add(g, "KW_A514", "PI514", "Ciśnienie sprężonego powietrza AKP", "Instrument air pressure", "bar", 0, 10, "%.2f", (5.5, None, 4.5, None))
add(g, "KW_A515", "TI514", "Punkt rosy sprężonego powietrza", "Instrument air dew point", "°C", -60, 20, "%.0f", (None, -20, None, -10))
for k in range(2):
    state(g, f"KW_D{505+k}", f"MS51{5+k}", f"Sprężarka S51{5+k} - praca", f"Compressor S51{5+k} running")
g = f"{G}/Energia elektryczna"
add(g, "KW_A516", "JI516", "Moc pobierana z sieci", "Power drawn from the grid", "kW", 0, 8000, "%.0f")
add(g, "KW_A517", "EI516", "Napięcie na szynach rozdzielni 6 kV", "6 kV switchboard voltage", "kV", 0, 7.5, "%.2f", (5.7, 6.6, 5.4, 6.9))
add(g, "KW_A518", "JI518", "Współczynnik mocy cos φ", "Power factor cos φ", "", 0, 1, "%.3f", (0.93, None, 0.9, None))
add(g, "KW_D507", "JQ516", "Licznik energii pobranej", "Energy drawn, meter", "kWh", 0, 4000000000, "%u", dtype="UI4", sample=60)
g = f"{G}/Ścieki"
add(g, "KW_A519", "AI519", "pH ścieków na wylocie z neutralizacji", "Effluent pH after neutralisation", "pH", 0, 14, "%.2f", (6.5, 9.0, 6.0, 9.5))
add(g, "KW_A520", "FI519", "Przepływ ścieków", "Effluent flow", "m3/h", 0, 100, "%.1f")

# ---------------------------------------------------------------- diagnostics and limits
g = "Diagnostyka/Łącza sterowników"
add(g, "KW_K000", "", "Stan łącza z serwerem asix (0 = poprawne)", "asix server link state (0 = OK)", "", 0, 32767, "%d", dtype="I2", control=False)
for section, (channel, ctl, _) in SECTIONS.items():
    add(g, ctl, "", f"Zmienna kontrolna sterownika kanału {channel} (0 = poprawna praca)",
        f"Control variable of the {channel} PLC (0 = healthy)", "", 0, 32767, "%d", dtype="I2", control=False)
g = "Diagnostyka/Limity"
limits = [
    ("KW_L001", "Limit ostrzegawczy temperatury pieca", "Furnace temperature warning limit", "°C", 0, 1200, 1080),
    ("KW_L002", "Limit alarmowy temperatury pieca", "Furnace temperature alarm limit", "°C", 0, 1200, 1120),
    ("KW_L003", "Limit alarmowy niskiego poziomu w walczaku", "Drum low level alarm limit", "mm", -200, 200, -150),
    ("KW_L004", "Limit alarmowy stężenia SO2 z pieca", "Furnace SO2 alarm limit", "%", 0, 15, 12.5),
    ("KW_L005", "Dopuszczalna emisja SO2 - ostrzeżenie", "SO2 emission warning limit", "mg/Nm3", 0, 2000, 800),
    ("KW_L006", "Dopuszczalna emisja SO2 - alarm", "SO2 emission alarm limit", "mg/Nm3", 0, 2000, 1000),
]
for name, pl, en, unit, lo, hi, _default in limits:
    add(g, name, "", pl, en, unit, lo, hi, "%.1f", writable=True, control=False, sample=60)


def write():
    here = os.path.dirname(os.path.abspath(__file__))
    names = [r["Name"] for r in rows]
    assert len(names) == len(set(names)), "duplicate names"
    aliases = [r["Alias"] for r in rows if r["Alias"]]
    assert len(aliases) == len(set(aliases)), "duplicate aliases"
    with open(os.path.join(here, "atrybuty.csv"), "w", encoding="utf-8-sig", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS, delimiter=";", lineterminator="\r\n")
        w.writeheader()
        w.writerows(rows)
    with open(os.path.join(here, "wytwornia_kwasu.zez"), "w", encoding="utf-8", newline="\n") as f:
        f.write("; Zestaw zmiennych aplikacji demonstracyjnej Wytwornia_Kwasu (wytwórnia kwasu siarkowego).\n")
        f.write("; Wygenerowany przez generate.py - format: docs/variable-database.md\n")
        f.write("Title = Wytwórnia kwasu siarkowego\n")
        f.write("Attributes = atrybuty.csv\n")
        for group in group_order:
            f.write(f"\n[{group}]\n")
            for name in groups[group]:
                f.write(f"{name}\n")
    print(f"{len(rows)} variables, {len(group_order)} groups")


write()
