/* DWAA/DWAB decoding through OpenEXR's C++ library (see exr_dwa_fallback.h). */
#include "io/exr_dwa_fallback.h"

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputPart.h>
#include <ImfMultiPartInputFile.h>

#include <cstdio>
#include <exception>
#include <new>

namespace {

void set_error(char *err, size_t err_size, const char *what)
{
    if (err && err_size)
        std::snprintf(err, err_size, "%s", what);
}

} // namespace

extern "C" int fx_dwa_read_part(const char *path, int part, const fx_dwa_channel *channels,
                                int count, char *err, size_t err_size)
{
    try {
        Imf::MultiPartInputFile file(path);
        if (part < 0 || part >= file.parts()) {
            set_error(err, err_size, "part index out of range");
            return 1;
        }
        Imf::InputPart in(file, part);
        const Imath::Box2i dw = in.header().dataWindow();
        Imf::FrameBuffer fb;
        for (int i = 0; i < count; i++) {
            const fx_dwa_channel &c = channels[i];
            if (!in.header().channels().findChannel(c.name)) {
                set_error(err, err_size, "channel vanished between header and pixels");
                return 1;
            }
            /* Slice::Make wants the address of the data window's first pixel; the
             * caller's buffer may start elsewhere (a frame holding several parts). */
            float *at = c.first + (ptrdiff_t)(dw.min.y - c.origin_y) * (ptrdiff_t)c.line_stride +
                        (ptrdiff_t)(dw.min.x - c.origin_x) * (ptrdiff_t)c.pixel_stride;
            fb.insert(c.name, Imf::Slice::Make(Imf::FLOAT, at, dw, c.pixel_stride * sizeof(float),
                                               c.line_stride * sizeof(float)));
        }
        in.setFrameBuffer(fb);
        in.readPixels(dw.min.y, dw.max.y);
        return 0;
    } catch (const std::bad_alloc &) {
        set_error(err, err_size, "out of memory");
        return 2;
    } catch (const std::exception &e) {
        set_error(err, err_size, e.what());
        return 1;
    } catch (...) {
        set_error(err, err_size, "unknown C++ exception");
        return 1;
    }
}
