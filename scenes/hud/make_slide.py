# Draws scenes/hud/slide.png, the HUD slide: a speed readout "72 km/h" in seven-segment digits and a turn
# arrow, on black (128 × 64, sRGB). Run: python3 scenes/hud/make_slide.py
import os, struct, zlib
W, H = 128, 64
img = [[(0, 0, 0) for _ in range(W)] for _ in range(H)]
def rect(x0, y0, x1, y1, c):
    for y in range(max(0, y0), min(H, y1)):
        for x in range(max(0, x0), min(W, x1)):
            img[y][x] = c
SEG = {'0': 'abcdef', '1': 'bc', '2': 'abged', '3': 'abgcd', '4': 'fgbc', '5': 'afgcd', '6': 'afgedc',
       '7': 'abc', '8': 'abcdefg', '9': 'abcdfg'}
def digit(ch, x, y, w=22, h=40, s=5, c=(170, 255, 235)):
    segs = SEG[ch]
    m = h // 2
    if 'a' in segs: rect(x, y, x + w, y + s, c)
    if 'g' in segs: rect(x, y + m - s // 2, x + w, y + m - s // 2 + s, c)
    if 'd' in segs: rect(x, y + h - s, x + w, y + h, c)
    if 'f' in segs: rect(x, y, x + s, y + m, c)
    if 'b' in segs: rect(x + w - s, y, x + w, y + m, c)
    if 'e' in segs: rect(x, y + m, x + s, y + h, c)
    if 'c' in segs: rect(x + w - s, y + m, x + w, y + h, c)
FONT = {  # 3x5 glyphs
    'k': ['1..', '1.1', '11.', '1.1', '1.1'], 'm': ['...', '11.', '111', '1.1', '1.1'],
    '/': ['..1', '..1', '.1.', '1..', '1..'], 'h': ['1..', '1..', '11.', '1.1', '1.1']}
def text(t, x, y, scale=2, c=(170, 255, 235)):
    for ch in t:
        for r, row in enumerate(FONT[ch]):
            for k, v in enumerate(row):
                if v == '1':
                    rect(x + k * scale, y + r * scale, x + (k + 1) * scale, y + (r + 1) * scale, c)
        x += 4 * scale
# Turn arrow (pointing right), green, on the left.
g = (60, 255, 110)
rect(6, 34, 24, 41, g)          # shaft
rect(6, 20, 13, 41, g)          # stem going up
for i in range(12):             # head
    rect(24 + i, 26 + i, 25 + i, 49 - i, g)
digit('7', 46, 8)
digit('2', 74, 8)
text('km/h', 98, 48)
rect(0, 0, W, 1, (40, 90, 80)); rect(0, H - 1, W, H, (40, 90, 80))   # thin frame
rect(0, 0, 1, H, (40, 90, 80)); rect(W - 1, 0, W, H, (40, 90, 80))
raw = b''.join(b'\x00' + bytes(v for px in row for v in px) for row in img)
def chunk(tag, data):
    return struct.pack('>I', len(data)) + tag + data + struct.pack('>I', zlib.crc32(tag + data) & 0xffffffff)
png = b'\x89PNG\r\n\x1a\n' + chunk(b'IHDR', struct.pack('>IIBBBBB', W, H, 8, 2, 0, 0, 0)) + \
      chunk(b'sRGB', b'\x00') + chunk(b'IDAT', zlib.compress(raw, 9)) + chunk(b'IEND', b'')
open(os.path.join(os.path.dirname(os.path.abspath(__file__)), 'slide.png'), 'wb').write(png)
